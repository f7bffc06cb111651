"""Draw the figure gallery: every command that writes figures, run on the bundled defaults.

    python tools/make_gallery.py [--only simulate visibility ...] [--docs DIR]

Runs each command of :data:`RUNS` as a user would (``python -m leosop ...
--out DIR``, no network, bundled element sets and recording), copies the PNG
files it wrote to ``docs/gallery/<run>-<file>.png`` and writes
``docs/gallery.md``: the command line, what it printed, and each figure with
its caption. Figures the captions below do not know yet are listed as such,
so a new figure shows up in the gallery the next time this runs.

The PNG files are not committed (``docs/gallery/.gitignore``): they are
products of the plotting code and would go stale with every change of it;
this script is their source and takes a few minutes.
"""

import argparse
import json
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from importlib.resources import files
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RECORDING = str(files("leosop") / "data" / "starlink_xian_snapshots.sigmf-meta")
#: A Monte Carlo study small enough for the gallery (the bundled table5/table6 specs
#: fly 160 full flights); the script writes it as ``small.json`` and shows it on the page.
SMALL_SPEC = {
    "name": "small",
    "description": "Starlink/INS error vs EKF correction period, both couplings, 120 s of xian-baoji, 3 seeds",
    "scenario": {"name": "xian-baoji-120s", "duration_s": 120},
    "fixed": {"level": "measurement"},
    "parameters": {"correction_period_s": [1, 10, 30], "coupling": ["loose", "tight"]},
    "n_seeds": 3,
}

#: name -> (arguments after ``leosop``, what the run shows, {figure file: caption}).
RUNS = {
    "simulate": (
        ["simulate"],
        "The main job: [Shen 2024]'s Xi'an -> Baoji flight at signal level, loose coupling, seed 0.",
        {
            "trajectory.png": "Truth, INS-only and Starlink/INS tracks (longitude/latitude) and heights.",
            "errors_3d.png": "3D position and velocity errors of the INS alone, the LEO snapshot fixes and the "
                             "fused solution, with the filter's 3D 3 sigma (3 x root of the covariance trace).",
            "errors_enu.png": "Fused position error east, north and up inside the filter's +-3 sigma.",
            "visible.png": "Visible satellites along the flight; 7 are needed for a snapshot fix.",
            "gdop.png": "Doppler GDOP along the flight (position [m], velocity [m/s] and clock [Hz] "
                              "standard deviations per 1 Hz of Doppler noise, root-sum-squared; see "
                              "[visibility](visibility.md#what-the-doppler-gdop-means)).",
        },
    ),
    "visibility": (
        ["visibility"],
        "One hour at Xi'an over the bundled Walker constellation, 40 deg mask.",
        {
            "visibility.png": "Visible satellites, Doppler GDOP and the classic range DOPs over the hour.",
            "skyplot.png": "The sky at the first epoch: satellites above the mask labelled, their next 10 min of track.",
        },
    ),
    "doppler": (
        ["doppler", RECORDING, "--block-s", "0.02"],
        "Doppler of the strongest pilot comb in each 20 ms snapshot capture of the bundled recording (one block "
        "per capture: longer blocks would join captures across their 2 s gaps).",
        {"spectrogram.png": "Spectrogram of the recording with the estimated Doppler track."},
    ),
    "replay": (
        ["replay", RECORDING, "--static"],
        "Every comb of the bundled recording found, tracked, identified against the bundled element sets (global "
        "search, no prior) and one static fix.",
        {"spectrogram.png": "Spectrogram with the identified tracks labelled by satellite."},
    ),
    "gdop-map": (
        ["study", "gdop-map", "--duration-s", "3600", "--step-s", "600", "--grid-deg", "5", "--scheduler", "serial"],
        "Visible count and Doppler GDOP over a 5 deg world grid, one hour in 10 min steps.",
        {
            "fix_fraction.png": "Fraction of the epochs with a Doppler fix possible (>= 7 satellites) per cell.",
            "n_visible_maps.png": "Visible satellites at a few instants.",
            "gdop_maps.png": "Doppler GDOP at the same instants.",
        },
    ),
    "montecarlo": (
        ["study", "montecarlo", "small.json", "--scheduler", "serial"],
        "A Monte Carlo study of the fusion flight (`small.json` below: a grid of parameters x seeds).",
        {
            "error_vs_correction_period_s.png": "Mean fused error over the seeds against the correction period, "
                                                "one line per coupling, 10-90 % band.",
            "error_vs_coupling.png": "The same against the coupling, one line per correction period.",
        },
    ),
    "align-fig2": (
        ["reproduce", "align-fig2", "--scheduler", "serial"],
        "[Qu 2024]'s Fig. 1-2: coarse-alignment errors against pitch, Monte Carlo.",
        {
            "align_pitch_roll_error.png": "Largest pitch and roll errors of algorithms 1, 2 and the Wahba solution "
                                          "against pitch.",
            "align_yaw_error.png": "Largest yaw error against pitch, the paper's values at 80 deg marked.",
        },
    ),
}


def _run(name, argv, out):
    """Run one command in ``out``'s parent; its printed summary without runtimes (they would change the page
    every run)."""
    cmd = [sys.executable, "-m", "leosop", *argv, "--out", str(out)]
    proc = subprocess.run(cmd, cwd=out.parent, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"make_gallery: {name}: exit {proc.returncode}: {proc.stderr.strip()}")
    printed = proc.stdout.strip().replace(str(out), f"out/{name}")
    return "\n".join(line for line in printed.splitlines() if not re.search(r"runtime|\d s on this process", line))


def _shown(argv):
    """The command line as a user types it (the bundled recording by its documented link)."""
    return "leosop " + " ".join("signals/starlink_xian_snapshots.sigmf-meta" if a == RECORDING else shlex.quote(a)
                                for a in argv)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", choices=sorted(RUNS), help="run only these (the page lists only them)")
    parser.add_argument("--docs", type=Path, default=ROOT / "docs", help="docs folder (default: the repository's)")
    args = parser.parse_args(argv)
    gallery = args.docs / "gallery"
    gallery.mkdir(parents=True, exist_ok=True)
    lines = ["# Figure gallery", "",
             "Made by `python tools/make_gallery.py` (do not edit by hand): each command run on the bundled "
             "defaults, its printed summary and the figures it wrote. The PNG files are not in the repository; "
             "run the script to draw them into `docs/gallery/`.", ""]
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "small.json").write_text(json.dumps(SMALL_SPEC, indent=2) + "\n")
        for name in args.only or RUNS:
            run_argv, what, captions = RUNS[name]
            out = Path(tmp) / name
            print(f"make_gallery: {_shown(run_argv)}", file=sys.stderr)
            printed = _run(name, run_argv, out)
            lines += [f"## {name}", "", what, ""]
            if "small.json" in run_argv:
                lines += ["```json", json.dumps(SMALL_SPEC, indent=2), "```", ""]
            lines += ["```sh", f"{_shown(run_argv)} --out out/{name}", "```", "", "Printed:", "", "```text", printed,
                      "```", ""]
            written = {p.name: p for p in out.glob("*.png")}
            for png in [written[n] for n in captions if n in written] + sorted(
                    p for n, p in written.items() if n not in captions):
                target = gallery / f"{name}-{png.name}"
                shutil.copyfile(png, target)
                caption = captions.get(png.name, "(no caption yet: new figure)")
                lines += [f"### `{png.name}`", "", caption, "", f"![{name} {png.name}](gallery/{target.name})", ""]
            missing = sorted(set(captions) - set(written))
            if missing:
                lines += [f"Not written by this run: {', '.join(missing)}.", ""]
    (args.docs / "gallery.md").write_text("\n".join(lines).rstrip() + "\n")
    print(f"make_gallery: wrote {args.docs / 'gallery.md'} and {gallery}/*.png", file=sys.stderr)


if __name__ == "__main__":
    main()
