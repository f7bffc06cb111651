"""Replay of IQ recordings: combs found per block, tracked, identified, fixed.

A recording (SigMF, one or many captures) is read block by block; every
pilot comb in a block is detected and estimated; detections are joined into
:class:`~leosop.replay.tracks.Track` objects across blocks and capture gaps;
each track is identified against a TLE snapshot; the identified tracks become
Doppler measurements for a position fix.
"""
