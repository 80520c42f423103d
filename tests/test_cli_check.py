"""`mitld-lp check`: output, exit codes 0/2 (and 1 for internal errors), one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from mitld_lp.cli import main

PAPER = "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"


def test_check_paper_formula(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", PAPER]) == 0
    out, err = capsys.readouterr()
    assert err == ""
    lines = dict(line.split(":", 1) for line in out.splitlines())
    printed = "D[mu1] b1 & F (b1 & F[0,3] A) | D[mu2] b2 & F (b2 & F[0,3] B)"
    assert lines["formula"].strip() == printed
    assert lines["events"].strip() == "b1 ~ mu1, b2 ~ mu2"
    assert lines["horizon"].strip() == "unbounded"
    assert lines["supported"].strip() == "yes"


def test_check_bounded_formula(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "G[0,3] (p -> X q)"]) == 0
    out, _ = capsys.readouterr()
    lines = dict(line.split(":", 1) for line in out.splitlines())
    assert lines["formula"].strip() == "G[0,3] (!p | X q)"
    assert lines["nnf"].strip() == "false R[0,3] (!p | X q)"
    assert lines["events"].strip() == "none"
    assert lines["horizon"].strip() == "4"  # q read at step 3 + 1


@pytest.mark.parametrize(
    ("formula", "fragment"),
    [
        ("F[0,3] p & D[mu] b", "co-safe"),
        ("G !h", "safety"),
        ("!h W goal", "safety"),
        ("G (p -> F[0,3] q)", "safety"),
        ("G !h & (D[mu] bus & F(bus & F[0,3] stop))", "obligation"),
    ],
)
def test_check_reports_the_class(
    formula: str, fragment: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check", formula]) == 0
    lines = dict(line.split(":", 1) for line in capsys.readouterr().out.splitlines())
    assert lines["class"].strip() == fragment
    assert main(["check", "--json", formula]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["class"] == fragment and data["co_safe"] == (fragment == "co-safe")


def test_check_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "--json", "F[0,3] p & D[pmf(0.1, 0.3)] b"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data == {
        "formula": "F[0,3] p & D[pmf(0.1, 0.3)] b",
        "nnf": "F[0,3] p & D[pmf(0.1, 0.3)] b",
        "events": {"b": "pmf(0.1, 0.3)"},
        "horizon": None,
        "co_safe": True,
        "class": "co-safe",
        "supported": True,
    }


@pytest.mark.parametrize(
    ("formula", "needle"),
    [
        ("p & (q", "1:7: unexpected end of input"),  # syntax error with line:column
        ("p & & q", "1:5: unexpected '&'"),
        ("F[3,1] p", "1:2: empty interval [3,1]"),  # l > u
        ("D[geometric(0.1, 0.2)] a", "1:3: geometric"),  # bad literal shape
        ("D[nosuch(1)] a", "unknown distribution family"),
        ("!D[mu] a", "under negation"),  # distribution under negation
        ("D[mu] a -> p", "under negation"),
        ("D[mu] a & D[nu] a", "already has the distribution"),
        ("D[mu] (a | b)", "directly to an event"),
        ("G F p", "1:1: G F p is a recurrence formula"),  # not an obligation
        ("p & F G p", "1:5: F G p is a persistence formula"),
    ],
)
def test_check_errors_exit_2_with_one_line(
    formula: str, needle: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check", formula]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.count("\n") == 1
    assert err.startswith("mitld-lp: error: ")
    assert needle in err
    assert "Traceback" not in err


def test_check_json_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "--json", "p &"]) == 2
    out, err = capsys.readouterr()
    data = json.loads(out)
    assert data["supported"] is False
    assert (data["line"], data["column"]) == (1, 4)
    assert err.startswith("mitld-lp: error: 1:4:")


def test_usage_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    # bare `mitld-lp`: one line naming the commands, the program named once
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].count("mitld-lp:") == 1, err
    assert "give a command: check," in err[0] and " solve," in err[0] and "--help" in err[0]
    assert main(["frobnicate"]) == 2
    assert main(["check"]) == 2
    assert main(["--help"]) == 0
    assert "check" in capsys.readouterr().out


def test_internal_error_exits_1_without_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def boom(_f: object) -> None:
        raise RuntimeError("something broke\nsecond line")

    from mitld_lp.cli import formulas

    monkeypatch.setattr(formulas, "check", boom)
    assert main(["check", "p"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith("mitld-lp: internal error: RuntimeError: something broke")


def _script() -> str:
    path = Path(sys.executable).with_name("mitld-lp")
    if not path.exists():
        pytest.skip("the mitld-lp console script is not installed next to this python")
    return str(path)


def test_installed_script() -> None:
    script = _script()
    ok = subprocess.run([script, "check", PAPER], capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0, ok.stderr
    assert "supported: yes" in ok.stdout
    bad = subprocess.run([script, "check", "G F p"], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2
    assert bad.stdout == ""
    assert bad.stderr.strip().splitlines() == [
        "mitld-lp: error: 1:1: G F p is a recurrence formula (an unbounded always/release over "
        "an unbounded eventually/until, like G F p, asks for something infinitely often); "
        "supported are co-safe, safety and obligation formulas (&/| combinations of formulas "
        "without unbounded G/R/W and formulas without unbounded F/U)"
    ]
