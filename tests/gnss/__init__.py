"""Tests of leosop.gnss."""
