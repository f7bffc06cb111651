"""`leosop reproduce` text output: ours beside the paper's, readable without --json."""

from leosop.cli import main


def test_text_table_shows_our_numbers_beside_the_papers(capsys):
    assert main(["reproduce", "errmodel-table3"]) == 0
    out = capsys.readouterr().out.splitlines()
    header = out[1].split()
    assert "att_err_deg" in header and "paper.pos_err_m" in header
    # [Chu 2009] Table 3, 100 mg row: 147.1 m/s and 11032.5 m, ours and the paper's.
    last = out[7].split()
    assert last[header.index("vel_err_mps")] == last[header.index("paper.vel_err_mps")] == "147.1"
    assert last[header.index("pos_err_m")] == last[header.index("paper.pos_err_m")] == "1.103e+04"


def test_unknown_target_is_bad_input(capsys):
    assert main(["reproduce", "table99"]) == 2
    assert "unknown target 'table99'" in capsys.readouterr().err


def test_help_names_every_target_with_its_paper(capsys):
    import re

    import pytest

    from leosop.apps.repro import TARGETS

    with pytest.raises(SystemExit):
        main(["reproduce", "--help"])
    out = capsys.readouterr().out
    for name, target in TARGETS.items():
        assert re.fullmatch(r"\[[A-Z][a-z]+ \d{4}\]", target.paper), name
        assert re.search(rf"^\s+{re.escape(name)}\s+{re.escape(target.help)}$", out, re.M), name
