"""Tests of leosop.positioning."""
