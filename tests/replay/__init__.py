"""Tests of leosop.replay."""
