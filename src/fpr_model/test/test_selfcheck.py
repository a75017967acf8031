"""The selfcheck console script passes and prints the Table 2.1 rows."""

from fpr_model import selfcheck


def test_selfcheck_passes(capsys):
    assert selfcheck.main([]) == 0
    out = capsys.readouterr().out
    assert "|M_RNEA - M_CRBA|" in out and "ALL CHECKS PASSED" in out
