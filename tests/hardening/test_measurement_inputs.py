"""Damaged measurement tables and positioning inputs: each gives a one-line InputError naming the file and line."""

import io
import lzma
import tarfile

import pytest

from leosop.cli import main
from leosop.errors import InputError
from leosop.positioning.datasets import read_doptrack, read_fll


def _one_line_error(call, *match):
    with pytest.raises(InputError) as info:
        call()
    text = str(info.value)
    assert "\n" not in text
    for part in match:
        assert part in text
    return text


def _xz_tar(files):
    """Bytes of a tar.xz archive holding ``{name: text}``."""
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:xz") as tar:
        for name, text in files.items():
            data = text.encode()
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return buf.getvalue()


@pytest.mark.parametrize("damage, message", [
    (lambda b: b[:len(b) // 2], "truncated"),
    (lambda b: b"", "not an xz-compressed tar archive"),
    (lambda b: b"time,frequency\n", "not an xz-compressed tar archive"),
    (lambda b: lzma.compress(b"no tar inside"), "not an xz-compressed tar archive"),
], ids=["truncated", "empty", "text", "xz-not-tar"])
def test_doptrack_damaged_archive(tmp_path, damage, message):
    (tmp_path / "data.tar.xz").write_bytes(damage(_xz_tar({"data/pass.csv": "0.0,145870000.0\n" * 200})))
    _one_line_error(lambda: read_doptrack(tmp_path), "data.tar.xz", message)


def test_doptrack_truncated_archive_is_exit_2(tmp_path, capsys):
    archive = _xz_tar({"data/pass.csv": "0.0,145870000.0\n" * 200})
    (tmp_path / "data.tar.xz").write_bytes(archive[:len(archive) // 2])
    assert main(["position", str(tmp_path), "--format", "doptrack", "--static"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "data.tar.xz: truncated" in err


_FLL = "index,doppler_offset,timestamp,measured_freq\n0,2240.5,2018-01-13T16:12:01.862011Z,145882240.5\n"


@pytest.mark.parametrize("last, message", [
    ("1,2239.0,2018", "fll.csv:3: no measured_freq field"),
    ("1,2239.0,2018-01-13T16:12:01.962011Z,1458822x", "fll.csv:3: measured_freq '1458822x' is not a number"),
    ("1,2239.0,2018-01-13T25:12:01Z,145882239.0", "fll.csv:3: timestamp: '2018-01-13T25:12:01Z'"),
], ids=["cut-off", "number", "time"])
def test_fll_bad_last_line_names_line_and_field(tmp_path, last, message):
    path = tmp_path / "fll.csv"
    path.write_text(_FLL + last)
    _one_line_error(lambda: read_fll(path, "43137"), message)
