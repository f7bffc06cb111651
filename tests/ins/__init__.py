"""Tests of leosop.ins."""
