"""Tests of leosop.geometry."""
