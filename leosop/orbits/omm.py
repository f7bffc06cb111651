"""CelesTrak OMM element sets (JSON and CSV) as a :class:`Constellation`."""

import csv
import json
import os
from datetime import datetime
from pathlib import Path

import numpy as np
from sgp4 import omm
from sgp4.api import Satrec

from ..errors import InputError
from ..fileio import check_input_file
from .constellation import Constellation
from .tle import check_elements, satrec_epoch_utc

__all__ = ["read_omm", "parse_omm"]

_REQUIRED = ("OBJECT_NAME", "NORAD_CAT_ID", "EPOCH", "MEAN_MOTION", "ECCENTRICITY", "INCLINATION",
             "RA_OF_ASC_NODE", "ARG_OF_PERICENTER", "MEAN_ANOMALY", "BSTAR", "MEAN_MOTION_DOT",
             "MEAN_MOTION_DDOT")
_DEFAULTS = {"CLASSIFICATION_TYPE": "U", "OBJECT_ID": "", "EPHEMERIS_TYPE": "0", "ELEMENT_SET_NO": "999",
             "REV_AT_EPOCH": "0"}
_NUMBERS = ("MEAN_MOTION", "ECCENTRICITY", "INCLINATION", "RA_OF_ASC_NODE", "ARG_OF_PERICENTER", "MEAN_ANOMALY",
            "BSTAR", "MEAN_MOTION_DOT", "MEAN_MOTION_DDOT")
_WHOLE_NUMBERS = ("EPHEMERIS_TYPE", "ELEMENT_SET_NO", "REV_AT_EPOCH")
#: Largest catalogue number SGP4 takes (Alpha-5 ``Z9999``).
_MAX_CATALOGUE = 339999


def read_omm(path: str | os.PathLike[str]) -> Constellation:
    """Read a CelesTrak OMM file, JSON (``FORMAT=json``) or CSV (``FORMAT=csv``).

    Parameters
    ----------
    path : str or Path
        The format is taken from the suffix (``.json`` or ``.csv``), else
        from the first non-blank character.

    Returns
    -------
    Constellation
    """
    path = Path(path)
    check_input_file(path, "OMM file")
    text = path.read_text(encoding="utf-8-sig", errors="replace")  # a BOM (spreadsheet exports) is not a field
    return parse_omm(text, str(path), fmt="json" if path.suffix.lower() == ".json" else None)


def parse_omm(text, source="<text>", *, fmt=None):
    """Parse OMM element sets from JSON or CSV text.

    Parameters
    ----------
    text : str
    source : str
        File name (or URL) used in messages.
    fmt : {"json", "csv"}, optional
        Default: JSON if the first non-blank character is ``[`` or ``{``, else CSV.

    Returns
    -------
    Constellation
    """
    if not text.strip():
        raise InputError(f"{source}: empty file, expected OMM element sets")
    if fmt == "json" or (fmt is None and text.lstrip().startswith(("[", "{"))):
        try:
            records = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"{source}:{exc.lineno}: invalid JSON ({exc.msg})") from None
        records = [records] if isinstance(records, dict) else records
        if not isinstance(records, list):
            raise InputError(f"{source}: expected a JSON list of OMM objects, found {type(records).__name__}")
        where = [f"{source}: record {k + 1}" for k in range(len(records))]
    else:
        records = list(csv.DictReader(text.splitlines()))
        where = [f"{source}:{k + 2}" for k in range(len(records))]
    names, satrecs = [], []
    for fields, at in zip(records, where):
        if not isinstance(fields, dict):
            raise InputError(f"{at}: expected an object of OMM fields")
        missing = [k for k in _REQUIRED if k not in fields or fields[k] in (None, "")]
        if missing:
            raise InputError(f"{at}: missing OMM field {missing[0]}")
        fields = {**_DEFAULTS, **{k: str(v) for k, v in fields.items() if v is not None}}
        _check_values(fields, at)
        if "." not in fields["EPOCH"]:
            fields["EPOCH"] += ".0"
        if len(fields["CLASSIFICATION_TYPE"]) != 1:
            raise InputError(f"{at}: OMM field CLASSIFICATION_TYPE: expected one character (U, C or S), "
                             f"found {fields['CLASSIFICATION_TYPE']!r}")
        sat = Satrec()
        try:
            omm.initialize(sat, fields)
        except (ValueError, KeyError, OverflowError, TypeError) as exc:
            raise InputError(f"{at}: bad OMM field value ({exc})") from None
        check_elements(sat, at)
        if sat.error:
            raise InputError(f"{at}: SGP4 rejects the element set (error code {sat.error})")
        names.append(fields["OBJECT_NAME"].strip())
        satrecs.append(sat)
    if not satrecs:
        raise InputError(f"{source}: no OMM element sets found")
    return Constellation(
        tuple(names),
        np.array([str(s.satnum) for s in satrecs]),
        tuple(satrecs),
        np.array([satrec_epoch_utc(s) for s in satrecs], dtype="datetime64[ns]"),
        str(source),
    )


def _check_values(fields, at):
    """Refuse a field SGP4's OMM reader cannot convert, or a catalogue number it should not take, naming the field."""
    for key in _NUMBERS:
        try:
            float(fields[key])
        except ValueError:
            raise InputError(f"{at}: OMM field {key}: expected a number, found {fields[key]!r}") from None
    for key in ("NORAD_CAT_ID", *_WHOLE_NUMBERS):
        try:
            value = int(fields[key])
        except ValueError:
            raise InputError(f"{at}: OMM field {key}: expected a whole number, found {fields[key]!r}") from None
        if key == "NORAD_CAT_ID" and not 1 <= value <= _MAX_CATALOGUE:
            raise InputError(f"{at}: OMM field NORAD_CAT_ID: expected a catalogue number 1..{_MAX_CATALOGUE}, "
                             f"found {value}")
    epoch = fields["EPOCH"]
    try:
        datetime.strptime(epoch, "%Y-%m-%dT%H:%M:%S.%f" if "." in epoch else "%Y-%m-%dT%H:%M:%S")
    except ValueError:
        raise InputError(f"{at}: OMM field EPOCH: expected a UTC time such as 2022-12-02T11:26:52.479456, "
                         f"found {epoch!r}") from None
