"""Tests of leosop.plots."""
