"""Every figure outside the paper reproductions, one module per source of data.

Modules: :mod:`.core` (Agg backend, atomic PNG files: :func:`pyplot`,
:func:`save_png`), :mod:`.simulation` (``leosop simulate`` runs, [Shen 2024]
Figs. 4 and 8-10: :func:`write_figures`), :mod:`.maps` (world maps of
``leosop study gdop-map``), :mod:`.sky` (visible count, GDOP and sky plot of
``leosop visibility``), :mod:`.spectra` (spectrogram with the Doppler track),
:mod:`.ppp` (PPP and PPP/INS runs), :mod:`.montecarlo` (error against each
swept parameter of ``leosop study montecarlo``).

The rule: figures depend on the domain packages, never the reverse. A domain
function that writes a figure imports its module inside the function, so
importing a domain package never imports this one or matplotlib; matplotlib
itself is imported only when a figure is drawn. A reproduction's figure stays
with its target in :mod:`leosop.apps.repro`.
"""

from .core import pyplot, save_png
from .simulation import write_figures

__all__ = ["pyplot", "save_png", "write_figures"]
