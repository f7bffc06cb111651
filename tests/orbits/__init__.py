"""Tests of leosop.orbits."""
