"""Tests of leosop.apps."""
