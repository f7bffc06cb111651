"""Tests of leosop.signal."""
