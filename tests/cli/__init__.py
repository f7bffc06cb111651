"""Tests of the commands (leosop.cli): each command's contract, one file per command."""
