"""Visibility over long spans in bounded memory: time chunks, passes stitched across them.

A day at 1 s is 86,400 epochs; a week, 604,800. :func:`visibility_chunks`
goes through a uniform grid a chunk of epochs at a time, each chunk a
:func:`~leosop.orbits.visibility.compute_visibility` of its own epochs, so the
working memory is set by the chunk and the caller keeps only what it writes
out. The visible set of an epoch does not depend on its neighbours (each
(satellite, epoch) pair is propagated and tested on its own), so the chunks
together are the whole-span result, pair for pair.

A pass can straddle chunk boundaries: :class:`PassStitcher` joins its pieces
and releases finished passes in the order of
:meth:`~leosop.orbits.visibility.Visibility.passes` (rise time, then id) as
soon as no pass still open can come before them.
"""

import numpy as np

from ..progress import progress
from ..timebase import utc_from_seconds
from .visibility import Pass, compute_visibility

__all__ = ["PassStitcher", "visibility_chunks"]


def visibility_chunks(constellation, start_utc, step_s, n_epochs, pos_rx_ecef_m, mask_deg, *, chunk_epochs,
                      screen=True, show_progress=True):
    """Visibility of a uniform grid, chunk by chunk.

    Epoch ``k`` is ``utc_from_seconds(k * step_s, start_utc)``, as in the
    whole-span grid, so every chunk's instants are those of that grid.

    Parameters
    ----------
    constellation : Constellation
    start_utc : numpy.datetime64
    step_s : float
    n_epochs : int
    pos_rx_ecef_m : array_like, (3,)
        A site.
    mask_deg : float
    chunk_epochs : int
        Epochs per chunk (the last may be shorter); a multiple of the 60 s
        screening step keeps the screen's coarse grid whole.
    screen : bool
        See :func:`~leosop.orbits.visibility.compute_visibility`.
    show_progress : bool
        One progress bar over the chunks on stderr (when it is a terminal).

    Yields
    ------
    first_epoch : int
        Index of the chunk's first epoch in the whole grid.
    Visibility
        The chunk's epochs, indexed from 0.
    """
    starts = range(0, n_epochs, chunk_epochs)
    for a in progress(starts, desc="visibility", unit="chunk") if show_progress else starts:
        times = utc_from_seconds(np.arange(a, min(a + chunk_epochs, n_epochs)) * step_s, start_utc)
        yield a, compute_visibility(constellation, times, pos_rx_ecef_m, mask_deg, screen=screen,
                                    show_progress=False)


class PassStitcher:
    """Passes of a grid seen chunk by chunk, released in whole-span order.

    Feed the chunks in order with :meth:`add`, then call :meth:`finish`;
    together they return exactly ``Visibility.passes()`` of the whole span.
    What is held between calls is the passes still open at the last chunk's
    end and the finished ones that an open pass rose before (for a LEO shell,
    about one pass duration's worth).

    Parameters
    ----------
    sat_ids : ndarray of str, (n_sats,)
    n_epochs : int
        Epochs of the whole grid (a pass up at its last epoch is truncated).
    """

    def __init__(self, sat_ids, n_epochs):
        self._sat_ids = sat_ids
        self._last_epoch = n_epochs - 1
        # sat index -> [rise_utc, rise_epoch, top_utc, top_elev_rad]; a pass up at the last chunk's end
        self._open = {}
        self._done = []  # (rise epoch, id, Pass) of the finished passes not yet released
        self._prev_end_utc = None  # the last epoch of the chunk before
        self.n_passes = 0

    def add(self, first_epoch, vis):
        """Take the next chunk; return the passes that can be released now.

        Parameters
        ----------
        first_epoch : int
            The chunk's first epoch in the whole grid.
        vis : Visibility
            The chunk (its epochs indexed from 0).

        Returns
        -------
        list of Pass
            By rise time, then id.
        """
        t = vis.times_utc
        last = len(t) - 1
        sat, first, end, top, top_el = vis.runs()
        still_open = {}
        for k, a, b, c, e in zip(sat.tolist(), first.tolist(), end.tolist(), top.tolist(), top_el.tolist()):
            piece = self._open.pop(k, None) if a == 0 else None
            if piece is None:
                piece = [t[a], first_epoch + a, t[c], e]
            elif e > piece[3]:  # the first of equal maxima stays the culmination
                piece[2:] = [t[c], e]
            if b == last and first_epoch + b < self._last_epoch:
                still_open[k] = piece
            else:
                self._close(k, piece, t[b], first_epoch + b)
        for k, piece in self._open.items():  # not up at this chunk's first epoch: set at the previous one's last
            self._close(k, piece, self._prev_end_utc, first_epoch - 1)
        self._open = still_open
        self._prev_end_utc = t[-1]
        return self._release(min((p[1] for p in still_open.values()), default=None))

    def finish(self):
        """The passes not released yet (none is open after the grid's last epoch)."""
        return self._release(None)

    def _close(self, k, piece, set_utc, set_epoch):
        rise_utc, rise_epoch, top_utc, top_el = piece
        sat_id = str(self._sat_ids[k])
        self._done.append((rise_epoch, sat_id, Pass(sat_id, rise_utc, top_utc, set_utc, float(np.degrees(top_el)),
                                                    bool(rise_epoch == 0 or set_epoch == self._last_epoch))))
        self.n_passes += 1

    def _release(self, before_epoch):
        """Finished passes that rose before epoch ``before_epoch`` (all if None), sorted; the rest kept.

        Sorted on (rise epoch, id), Python ints and strings: the order of (rise time, id) on a grid of
        increasing times, and several times faster to sort than datetime64 scalars.
        """
        ready = [d for d in self._done if before_epoch is None or d[0] < before_epoch]
        self._done = [d for d in self._done if not (before_epoch is None or d[0] < before_epoch)]
        return [d[2] for d in sorted(ready, key=lambda d: d[:2])]
