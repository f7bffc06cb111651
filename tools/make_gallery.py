"""Draw the figure gallery: every command that writes figures, run on the bundled defaults.

    python tools/make_gallery.py [--only simulate visibility ...] [--docs DIR] [--data DIR]

Runs each command of :data:`RUNS` as a user would (``python -m leosop ...
--out DIR``, no network, bundled element sets and recording; the PPP run reads
the ESBC00DNK day of ``../shared/data``), writes the PNG files it drew to
``docs/gallery/<run>-<file>.png`` as small palette PNGs (:func:`small_png`, at
most :data:`PNG_BUDGET_BYTES` each) and writes ``docs/gallery.md``
(:func:`render`): the command line, what it printed, and each figure with its
caption. Figures the captions below do not know yet are listed as such, so a
new figure shows up in the gallery the next time this runs.

The figures are committed so that the docs show them; ``tests/project/test_gallery.py``
checks that the page is what :func:`render` writes from the code's runs and
captions, that every figure it shows is there and small, and that the quickest
run still prints what the page says. The whole gallery takes 3.5 min (1.3 min of CPU) on a
shared 2-core machine.
"""

import argparse
import io
import json
import re
import shlex
import subprocess
import sys
import tempfile
from importlib.resources import files
from pathlib import Path

from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
RECORDING = str(files("leosop") / "data" / "starlink_xian_snapshots.sigmf-meta")
#: Where the PPP run's files are, relative to the shared data folder (``--data``), as the docs show it.
DATA_SHOWN = "../shared/data"
ESBC = "{data}/rinex/esbc_2020-177/"
#: Largest gallery PNG: the docs stay light (all of them well under 2 MB).
PNG_BUDGET_BYTES = 120_000
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
INTRO = ("Made by `python tools/make_gallery.py` (do not edit by hand; 3.5 min): each command run on the "
         "bundled defaults, its printed summary and the figures it wrote, kept in `docs/gallery/` as small "
         "palette PNGs.")

#: name -> (arguments after ``leosop``, what the run shows, {figure file: caption}).
RUNS = {
    "simulate": (
        ["simulate"],
        "The main job: [Shen 2024]'s Xi'an -> Baoji flight at signal level, loose coupling, seed 0.",
        {
            "trajectory.png": "Truth (thick, light), INS-only (dashed) and Starlink/INS (thin, dark) tracks in the "
                              "east/north plane of the start, equal scales, start and end marked, an inset of the end "
                              "in metres (the fused track lies metres from the truth); heights beside.",
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
            "skyplot.png": "The sky at the first epoch: satellites above the mask with their next 10 min of "
                           "track, elevation rings in degrees; in a crowded sky only the 12 highest are coloured "
                           "and labelled.",
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
        {"spectrogram.png": "Spectrogram with the identified tracks labelled by satellite in a column at the "
                            "right, each tied to its track's end by a line that crosses no label."},
    ),
    "gdop-map": (
        ["study", "gdop-map", "--duration-s", "3600", "--step-s", "600", "--grid-deg", "5", "--scheduler", "serial"],
        "Visible count and Doppler GDOP over a 5 deg world grid, one hour in 10 min steps.",
        {
            "fix_fraction.png": "Fraction of the epochs with a Doppler fix possible (>= 7 satellites) per cell.",
            "n_visible_maps.png": "Visible satellites at each of the 7 epochs (up to 9 are drawn, else evenly "
                                  "spaced ones, the title says which). The east-west stripes are real, not a "
                                  "drawing artefact: in the bundled Walker shells (phasing factor 1) the "
                                  "satellites of neighbouring planes fly nearly abreast, in rows about 12 deg of "
                                  "latitude apart; between rows a 40 deg mask sees 0-2 of them. A 1 deg grid "
                                  "shows the same rows, which a 5 deg grid samples as stripes.",
            "gdop_maps.png": "Doppler GDOP at the same epochs; blank cells see fewer than 7 satellites (the same "
                             "rows).",
        },
    ),
    "montecarlo": (
        ["study", "montecarlo", "small.json", "--scheduler", "serial"],
        "A Monte Carlo study of the fusion flight (`small.json` below: a grid of parameters x seeds).",
        {
            "error_vs_correction_period_s.png": "Mean fused error over the seeds against the correction period, "
                                                "one line per coupling (own marker and dash, points side by "
                                                "side: loose and tight nearly coincide), 10-90 % bars and band.",
            "error_vs_coupling.png": "The same against the coupling, one line per correction period.",
        },
    ),
    "ppp": (
        ["ppp", ESBC + "ESBC00DNK_R_20201770000_01D_30S_MO.crx.gz",
         "--nav", ESBC + "ESBC00DNK_R_20201770000_01D_MN.rnx.gz",
         "--sp3", ESBC + "GRG0MGXFIN_20201770000_01D_15M_ORB.SP3.gz",
         "--clk", ESBC + "GRG0MGXFIN_20201770000_01D_30S_CLK.CLK.gz",
         "--antex", ESBC + "esbc_2020-177.atx"],
        "Kinematic float PPP of the IGS station ESBC00DNK over 24 h with its antenna calibrations (the "
        "[PPP](ppp.md) page's day; needs "
        "`../shared/data`).",
        {"ppp.png": "Offsets east, north and up from the final position in cm with the filter's +-3 sigma band "
                    "(edges drawn, median printed, so a band thinner than the wander still shows), and the "
                    "satellites used."},
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


def _run(name, argv, out, data):
    """Run one command in ``out``'s parent; its printed summary without runtimes (they would change the page
    every run)."""
    cmd = [sys.executable, "-m", "leosop", *[a.format(data=data) for a in argv], "--out", str(out)]
    proc = subprocess.run(cmd, cwd=out.parent, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"make_gallery: {name}: exit {proc.returncode}: {proc.stderr.strip()}")
    printed = proc.stdout.strip().replace(str(out), f"out/{name}").replace(str(data), DATA_SHOWN)
    printed = re.sub(r", read [\d.]+ s, total [\d.]+ s", "", printed)  # the PPP summary's run times
    return "\n".join(line for line in printed.splitlines() if not re.search(r"runtime|\d s on this process", line))


def _shown(argv):
    """The command line as a user types it (the bundled recording by its documented link, the data folder
    as the docs name it)."""
    return "leosop " + " ".join("signals/starlink_xian_snapshots.sigmf-meta" if a == RECORDING
                                else shlex.quote(a.format(data=DATA_SHOWN)) for a in argv)


def small_png(src, dst, budget=PNG_BUDGET_BYTES):
    """Write ``src`` to ``dst`` as an optimised palette PNG of at most ``budget`` bytes.

    A palette of 256 colours by octree (which keeps the rare saturated colours of thin lines, where a median
    cut merges them into their neighbours), then 128, then 85 % of the size per step; returns the bytes
    written.
    """
    image = Image.open(src).convert("RGB")
    while True:
        for colors in (256, 128):
            buf = io.BytesIO()
            image.quantize(colors=colors, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE).save(
                buf, format="png", optimize=True)
            if buf.tell() <= budget:
                Path(dst).write_bytes(buf.getvalue())
                return buf.tell()
        image = image.resize((round(image.width * 0.85), round(image.height * 0.85)), Image.Resampling.LANCZOS)


def render(sections):
    """The page: ``sections`` is ``[(run name, printed text, [figure file names in page order]), ...]``."""
    lines = ["# Figure gallery", "", INTRO, ""]
    for name, printed, figures in sections:
        run_argv, what, captions = RUNS[name]
        lines += [f"## {name}", "", what, ""]
        if "small.json" in run_argv:
            lines += ["```json", json.dumps(SMALL_SPEC, indent=2), "```", ""]
        lines += ["```sh", f"{_shown(run_argv)} --out out/{name}", "```", "", "Printed:", "", "```text", printed,
                  "```", ""]
        for png in figures:
            caption = captions.get(png, "(no caption yet: new figure)")
            lines += [f"### `{png}`", "", caption, "", f"![{name} {png}](gallery/{name}-{png})", ""]
        missing = sorted(set(captions) - set(figures))
        if missing:
            lines += [f"Not written by this run: {', '.join(missing)}.", ""]
    return "\n".join(lines).rstrip() + "\n"


def parse(page):
    """The sections of a page :func:`render` wrote (its inverse): ``[(name, printed, figures), ...]``."""
    sections = []
    for block in re.split(r"^## ", page, flags=re.M)[1:]:
        name = block.split("\n", 1)[0]
        printed = re.search(r"^Printed:\n\n```text\n(.*?)\n```$", block, re.M | re.S).group(1)
        sections.append((name, printed, re.findall(r"^### `(.+)`$", block, re.M)))
    return sections


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", choices=sorted(RUNS), help="run only these (the page lists only them)")
    parser.add_argument("--docs", type=Path, default=ROOT / "docs", help="docs folder (default: the repository's)")
    parser.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data",
                        help="shared data folder with rinex/esbc_2020-177 for the PPP run (default: ../shared/data)")
    args = parser.parse_args(argv)
    gallery = args.docs / "gallery"
    gallery.mkdir(parents=True, exist_ok=True)
    sections = []
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "small.json").write_text(json.dumps(SMALL_SPEC, indent=2) + "\n")
        for name in args.only or RUNS:
            run_argv, _, captions = RUNS[name]
            if any("{data}" in a for a in run_argv) and not args.data.is_dir():
                raise SystemExit(f"make_gallery: {name}: --data {args.data}: no such folder (the PPP run reads "
                                 f"rinex/esbc_2020-177 there)")
            out = Path(tmp) / name
            print(f"make_gallery: {_shown(run_argv)}", file=sys.stderr)
            printed = _run(name, run_argv, out, args.data.resolve())
            written = {p.name: p for p in out.glob("*.png")}
            for stale in gallery.glob(f"{name}-*.png"):
                stale.unlink()
            figures = [n for n in captions if n in written] + sorted(set(written) - set(captions))
            for png in figures:
                small_png(written[png], gallery / f"{name}-{png}")
            sections.append((name, printed, figures))
    (args.docs / "gallery.md").write_text(render(sections))
    print(f"make_gallery: wrote {args.docs / 'gallery.md'} and {gallery}/*.png", file=sys.stderr)


if __name__ == "__main__":
    main()
