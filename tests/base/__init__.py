"""Tests of leosop's top-level modules (frames, earth, timebase, rotations, ...)."""
