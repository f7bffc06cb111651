"""Download current element sets of a CelesTrak group."""

import os
import re
import urllib.error
import urllib.parse
import urllib.request

from ..errors import ExternalError, InputError
from ..fileio import atomic_path
from .omm import parse_omm
from .tle import parse_tle_lines

__all__ = ["CELESTRAK_GP_URL", "fetch_group"]

#: CelesTrak's general-perturbations query endpoint; ``LEOSOP_CELESTRAK_URL``
#: overrides it (mirrors, tests against a local server).
CELESTRAK_GP_URL = "https://celestrak.org/NORAD/elements/gp.php"
_FORMATS = {"tle": "tle", "json": "json", "csv": "csv"}


def fetch_group(group, out_path, *, fmt="tle", base_url=None, timeout_s=30.0):
    """Download CelesTrak group ``group`` to ``out_path`` and check it parses.

    Parameters
    ----------
    group : str
        CelesTrak group name, e.g. ``starlink``, ``oneweb``, ``active``.
    out_path : str or Path
        Written only when the download is complete and every record parses.
    fmt : {"tle", "json", "csv"}
        TLE (3-line) or OMM JSON/CSV.
    base_url : str, optional
        Endpoint, an http(s) URL; default ``$LEOSOP_CELESTRAK_URL`` or :data:`CELESTRAK_GP_URL`.
    timeout_s : float

    Returns
    -------
    Constellation
        What was downloaded; its ``source`` is the URL.
    """
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", group or ""):
        raise InputError(f"GROUP {group!r}: expected a CelesTrak group name such as starlink or active")
    if fmt not in _FORMATS:
        raise InputError(f"fmt {fmt!r}: expected one of {', '.join(_FORMATS)}", param="fmt")
    base = base_url or os.environ.get("LEOSOP_CELESTRAK_URL") or CELESTRAK_GP_URL
    parts = urllib.parse.urlsplit(base)
    if parts.scheme not in ("http", "https") or not parts.netloc:
        name = "base_url" if base_url else "LEOSOP_CELESTRAK_URL"
        raise InputError(f"{name} {base!r}: expected an http:// or https:// URL such as {CELESTRAK_GP_URL}",
                         param="base_url" if base_url else ())
    url = f"{base}?{urllib.parse.urlencode({'GROUP': group, 'FORMAT': _FORMATS[fmt]})}"
    try:
        with urllib.request.urlopen(url, timeout=timeout_s) as resp:
            body = resp.read()
    except urllib.error.HTTPError as exc:
        raise ExternalError(f"{url}: server answered HTTP {exc.code} {exc.reason}") from None
    except (urllib.error.URLError, OSError) as exc:
        reason = getattr(exc, "reason", exc)
        raise ExternalError(f"cannot download {url}: {reason} "
                            "(no network? set LEOSOP_CELESTRAK_URL for a mirror)") from None
    text = body.decode("ascii", errors="replace").strip()
    if not text or text.lower().startswith(("invalid query", "no gp data found")):
        raise ExternalError(f"{url}: CelesTrak returned no element sets for group {group!r} ({text[:60]!r})")
    # Parsed before anything is written, so that messages name the URL (never a temporary file).
    try:
        if fmt == "tle":
            const = parse_tle_lines(body.splitlines(), url)
        else:
            const = parse_omm(body.decode("utf-8-sig", errors="replace"), url, fmt=fmt)
    except InputError as exc:
        raise ExternalError(f"downloaded data do not parse: {exc}") from None
    with atomic_path(out_path) as tmp:
        tmp.write_bytes(body)
    return const
