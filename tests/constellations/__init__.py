"""Tests of leosop.constellations."""
