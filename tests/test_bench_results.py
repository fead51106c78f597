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


def test_update_replaces_only_the_named_benchmarks(runner, tmp_path, monkeypatch):
    out = tmp_path / "RESULTS.md"
    runner.main(["--quick", "--results", str(out)])
    before = out.read_text()
    assert "| 4 | 12.5 |" in before
    # bench_alpha changes; only it is re-run, and bench_beta's row and section are kept
    alpha = tmp_path / "bench_alpha.py"
    alpha.write_text('"""Alpha speed: widgets per second."""\n\n'
                     'def main():\n    print("| n | widgets/s |\\n|---|---|\\n| 4 | 99.0 |")\n')
    monkeypatch.setattr(runner, "discover", lambda names=None: [alpha])
    monkeypatch.setattr(runner, "_commit", lambda: "abc1234")
    assert runner.main(["-k", "alpha", "--update", "--results", str(out)]) == 0
    text = out.read_text()
    alpha_section = text.split("## bench-alpha", 1)[1].split("## bench-beta")[0]
    assert "| 4 | 99.0 |" in alpha_section and "12.5" not in alpha_section
    assert "_Measured at abc1234" in alpha_section and "-k alpha --update" in alpha_section
    beta_section = text.split("## bench-beta", 1)[1]
    assert "_Measured at " in beta_section and "abc1234" not in beta_section
    assert "| [bench_beta](#bench-beta) | Beta accuracy | FAILED |" in text
    # the header names both commits the file now holds
    commit_row = next(line for line in text.splitlines() if line.startswith("| commit |"))
    assert "abc1234" in commit_row and "," in commit_row


def test_update_needs_a_name_and_a_file(runner, tmp_path):
    with pytest.raises(SystemExit) as exc:
        runner.main(["--update", "-k", "alpha", "--results", str(tmp_path / "none.md")])
    assert exc.value.code == 2
