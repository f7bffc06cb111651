"""The aids' state blocks in the engine's filter: where each sits in ``P``, its estimate, when it goes stale."""

import numpy as np

from .common import N_INS

__all__ = ["Blocks"]


class Blocks:
    """The :class:`leosop.fusion.aids.StateBlock` alive in the filter, after its INS and optional states.

    Each entry, by key: ``[block, first index in P, estimate (size,), time last named [s]]``.
    A block is added with its prior (uncorrelated) when the first aid naming
    it comes and dropped (marginalised: its rows and columns of ``P`` go) once
    stale, ``block.drop_after_s`` after the last aid that named it.
    """

    def __init__(self):
        self.entries = {}

    def admit(self, P, aid):
        """Drop the stale blocks, add those ``aid`` names for the first time, mark its blocks named now.

        Returns
        -------
        ndarray, (n_x', n_x')
            ``P`` (n_x, n_x) without the dropped blocks and with the added ones.
        """
        P = self.drop_stale(P, aid.t_s)
        for b in aid.states:
            if b.key not in self.entries:
                n = P.shape[0]
                grown = np.zeros((n + b.size, n + b.size))
                grown[:n, :n] = P
                grown[n:, n:] = np.diag(np.square(b.sigma0))
                P = grown
                self.entries[b.key] = [b, n, np.array(b.mean0, dtype=float), aid.t_s]
            self.entries[b.key][3] = aid.t_s
        return P

    def drop_stale(self, P, t_s):
        """``P`` (n_x, n_x) without the blocks stale at ``t_s`` (marginalised), the others' indices moved."""
        stale = [k for k, (b, _, _, last) in self.entries.items()
                 if b.drop_after_s is not None and t_s - last > b.drop_after_s]
        if stale:
            keep = np.ones(P.shape[0], dtype=bool)
            for k in stale:
                b, i = self.entries.pop(k)[:2]
                keep[i:i + b.size] = False
            P = P[np.ix_(keep, keep)]
            first = np.cumsum(keep) - 1
            for entry in self.entries.values():
                entry[1] = int(first[entry[1]])
        return P

    def clone(self, P, block, estimate, G, t_s):
        """Add ``block`` as a clone of ``G dx_ins`` (stochastic cloning): its estimate (k,), its rows ``G P_ins,:``.

        ``G`` (k, 15) maps the INS errors to the clone's; returns ``P`` (n_x + k, n_x + k).
        """
        n = P.shape[0]
        rows = G @ P[:N_INS]
        grown = np.zeros((n + block.size, n + block.size))
        grown[:n, :n] = P
        grown[n:, :n] = rows
        grown[:n, n:] = rows.T
        grown[n:, n:] = rows[:, :N_INS] @ G.T
        self.entries[block.key] = [block, n, np.array(estimate, dtype=float), t_s]
        return grown

    def alive(self, blocks):
        """Whether every cloned block of ``blocks`` is in the filter (the others are added when named)."""
        return all(b.key in self.entries for b in blocks if b.cloned)

    def restart(self, P, blocks):
        """Re-initialise alive ``blocks`` at their ``mean0``, ``sigma0`` in ``P`` (n_x, n_x, in place): uncorrelated."""
        for b in blocks:
            _, i, x, _ = self.entries[b.key]
            sl = slice(i, i + b.size)
            P[sl, :] = 0.0
            P[:, sl] = 0.0
            P[sl, sl] = np.diag(np.square(b.sigma0))
            x[:] = b.mean0

    def propagate(self, Phi, Qd, dt_s):
        """Write each block's transition and noise over ``dt_s`` into ``Phi``, ``Qd`` (n_x, n_x); move the estimates.

        ``Phi`` is the identity and ``Qd`` zero over the blocks on entry. A random walk's transition
        (:meth:`leosop.fusion.aids.StateBlock.transition`) is the identity, which leaves ``Phi`` and its
        estimate as they are, and its noise diagonal: all the walks' diagonals are written at once.
        """
        walks, psd = [], []
        for b, i, x, _ in self.entries.values():
            if b.integrated:
                sl = slice(i, i + b.size)
                Phi[sl, sl], Qd[sl, sl] = b.transition(dt_s)
                x[:] = Phi[sl, sl] @ x
            else:
                walks.append(np.arange(i, i + b.size))
                psd.append(b.psd)
        if walks:
            k = np.concatenate(walks)
            Qd[k, k] = np.concatenate(psd) * dt_s

    def design(self, aid, Ha, H):
        """Copy the INS and block columns of ``aid``'s design ``Ha`` (m, 15 + its blocks) into ``H`` (m, n_x)."""
        H[:, :N_INS] = Ha[:, :N_INS]
        c = N_INS
        for b in aid.states:
            i = self.entries[b.key][1]
            H[:, i:i + b.size] = Ha[:, c:c + b.size]
            c += b.size

    def feed_back(self, dx):
        """Remove the estimated errors ``dx`` (n_x,) from the blocks' estimates (error = estimate minus truth)."""
        for b, i, x, _ in self.entries.values():
            x -= dx[i:i + b.size]

    def estimates(self, dx):
        """The estimates by key, less the errors ``dx`` (n_x,)."""
        if not dx.any():
            return {k: e[2] for k, e in self.entries.items()}
        return {k: x - dx[i:i + b.size] for k, (b, i, x, _) in self.entries.items()}

    def layout(self):
        """``{key: (first index in P, estimate)}``."""
        return {k: (e[1], e[2]) for k, e in self.entries.items()}

    def summary(self, P):
        """``{key: (estimate, sigma)}``, copies, with the sigmas from ``P`` (n_x, n_x)."""
        return {k: (x.copy(), np.sqrt(np.diagonal(P)[i:i + b.size])) for k, (b, i, x, _) in self.entries.items()}
