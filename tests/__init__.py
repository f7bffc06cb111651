"""Tests of leosop; the layout is described in conftest.py."""
