"""``python -m benchmarks`` writes the generated results file: machine, date, load and
commit, one summary row per benchmark saying what it measures, then its tables."""

from __future__ import annotations

import importlib

import pytest


@pytest.fixture
def runner(tmp_path, monkeypatch):
    """The benchmark runner with two stand-in benchmarks (one fails) in ``tmp_path``."""
    main = importlib.import_module("benchmarks.__main__")
    ok = tmp_path / "bench_alpha.py"
    ok.write_text('"""Alpha speed: widgets per second. More prose."""\n\n'
                  'def main():\n    print("| n | widgets/s |\\n|---|---|\\n| 4 | 12.5 |")\n')
    bad = tmp_path / "bench_beta.py"
    bad.write_text('"""Beta accuracy."""\n\ndef main():\n    raise RuntimeError("broken")\n')
    monkeypatch.setattr(main, "discover", lambda names=None: [ok, bad])
    return main


def test_results_file_records_context_and_every_measurement(runner, tmp_path, capsys):
    out = tmp_path / "RESULTS.md"
    assert runner.main(["--quick", "--results", str(out)]) == 1  # one benchmark failed
    text = out.read_text()
    for field in ("| date |", "| commit |", "| machine |", "| load (1 / 5 / 15 min) |",
                  "| command | `python -m benchmarks --quick --results"):
        assert field in text
    # the summary row says what the benchmark measures (its docstring's first sentence)
    assert "| [bench_alpha](#bench-alpha) | Alpha speed: widgets per second | ok |" in text
    assert "| [bench_beta](#bench-beta) | Beta accuracy | FAILED |" in text
    # the benchmark's own table follows under its heading, as printed
    section = text.split("## bench-alpha", 1)[1]
    assert "| 4 | 12.5 |" in section.split("## bench-beta")[0]
    # and the terminal still saw it
    assert "| 4 | 12.5 |" in capsys.readouterr().out


def test_no_results_writes_nothing(runner, tmp_path):
    out = tmp_path / "RESULTS.md"
    runner.main(["--no-results", "--results", str(out)])
    assert not out.exists()
