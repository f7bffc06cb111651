"""Figure of ``leosop imu allan``: Allan deviations of gyros and accelerometers with the read-off terms marked."""

import numpy as np

from ..ins.allan import BIAS_INSTABILITY_FACTOR
from .core import pyplot, save_png

__all__ = ["allan"]

_AXES = ("R", "F", "U")


def allan(path, gyro, accel, gyro_scale, accel_scale, title):
    """Log-log Allan deviation per axis; dashed: ``N / sqrt(tau)`` (slope -1/2), dotted: the floor ``0.664 B``.

    ``gyro``, ``accel``: :class:`leosop.ins.allan.AllanResult`; ``*_scale`` turn their units into deg/h and ug.
    """
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    for ax, res, scale, unit, name in ((axes[0], gyro, gyro_scale, "deg/h", "gyro"),
                                       (axes[1], accel, accel_scale, "ug", "accelerometer")):
        for k in range(3):
            c = f"C{k}"
            ax.loglog(res.tau_s, res.adev[:, k] * scale, c, lw=1.2, label=f"{_AXES[k]}")
            ax.loglog(res.tau_s, res.white_density[k] * scale / np.sqrt(res.tau_s), c, ls="--", lw=0.8)
            ax.axhline(res.bias_instability[k] * BIAS_INSTABILITY_FACTOR * scale, color=c, ls=":", lw=0.8)
            ax.plot(res.tau_min_s[k], res.bias_instability[k] * BIAS_INSTABILITY_FACTOR * scale, c + "o", ms=4)
        ax.set_xlabel("averaging time tau [s]")
        ax.set_ylabel(f"Allan deviation [{unit}]")
        ax.set_title(name, fontsize=10)
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{title}: Allan deviation; dashed N / sqrt(tau) (random walk), dotted 0.664 B (bias instability)",
                 fontsize=10)
    save_png(fig, path)
