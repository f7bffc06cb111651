"""Tests of leosop.fusion."""
