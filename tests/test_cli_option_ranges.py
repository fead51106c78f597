"""Numeric options show their ranges in --help, and a bad option value is refused in one
line that names the option, never a file (the value is not the mesh's or the output's fault)."""

from __future__ import annotations

import click
import pytest
import trimesh

from shtools.cli._common import option_type, setting_type
from shtools.cli.main import cli


def _commands():
    ctx = click.Context(cli)

    def walk(cmd, path):
        if isinstance(cmd, click.Group):
            for name in cmd.list_commands(ctx):
                yield from walk(cmd.get_command(ctx, name), (*path, name))
        else:
            yield " ".join(path), cmd

    return list(walk(cli, ()))


def test_every_numeric_option_shows_a_range_and_no_missing_bound():
    plain, unbounded = [], []
    for name, cmd in _commands():
        for p in cmd.params:
            if p.type in (click.INT, click.FLOAT):
                plain.append(f"{name} {p.opts[0]}")
            if isinstance(p.type, click.types._NumberRangeBase):
                if "None" in p.type._describe_range():
                    unbounded.append(f"{name} {p.opts[0]}: {p.type._describe_range()}")
    assert plain == [] and unbounded == []


def test_scaling_help_shows_the_cone_angle_bounds(run_cli):
    code, out, _ = run_cli("tables", "scaling", "--help")
    help_text = " ".join(out.split())
    assert code == 0 and "None" not in help_text
    assert "[default: 45.0; 0<x<90]" in help_text


def test_field_sample_help_shows_its_ranges(run_cli):
    code, out, _ = run_cli("field", "sample", "--help")
    help_text = " ".join(out.split())
    assert code == 0
    for shown in ("[default: 32; 1<=x<=256]", "[default: 64; a power of two, 2<=x<=4096]",
                  "[default: 64; 4<=x<=1024]", "[default: 4; 1<=x<=8]",
                  "[default: 0.01; x>0]", "[default: 8; a power of two, 1<=x<=4096]",
                  "[default: 8; 1<=x<=8]", "[default: 0.05; 0<x<=1]"):
        assert shown in help_text, shown


@pytest.mark.parametrize(("name", "values"), [
    ("shells", range(-1, 260)),
    ("resolution", [*range(-1, 300), 4096, 8192, 2**70]),
    ("map_size", range(-1, 1100)),
    ("bits", range(-1, 12)),
    ("order", range(-1, 12)),
    ("threshold", (-1.0, 0.0, 1e-9, 0.5, 1.0, 1e9, float("inf"), float("nan"))),
])
def test_field_sample_types_accept_what_the_library_accepts(name, values):
    """The CLI's bounds of field sample are the library's (FieldParameters.validate)."""
    from shtools.errors import InputError
    from shtools.fields import FieldParameters

    kind = {"shells": option_type("shells"), "resolution": option_type("field_resolution"),
            "map_size": option_type("map_size"), "bits": option_type("bits"),
            "order": setting_type("order"), "threshold": option_type("threshold")}[name]
    for value in values:
        try:
            kind.convert(value, None, None)
            cli_ok = True
        except click.BadParameter:
            cli_ok = False
        try:
            FieldParameters(**{name: value}, min_resolution=1).validate()
            lib_ok = True
        except InputError:
            lib_ok = False
        assert cli_ok == lib_ok, (name, value)


@pytest.fixture
def box(tmp_path):
    path = tmp_path / "bunny.obj"
    trimesh.creation.box().export(path)
    return path


@pytest.mark.parametrize(("args", "named"), [
    (("--shells", 0), "'--shells': 0 is not in the range 1<=x<=256"),
    (("--bits", 12), "'--bits': 12 is not in the range 1<=x<=8"),
    (("--resolution", 30), "'--resolution': must be a power of two >= 2 and <= 4096, got 30 "
                         "(e.g. 16 or 32)"),
    (("--resolution", 0), "'--resolution': must be a power of two >= 2 and <= 4096, got 0 "
                        "(e.g. 2)"),
    (("--resolution", 8192), "got 8192 (e.g. 4096)"),
    # checked after parsing (the library's validate): still the option, no file
    (("--resolution", 8, "--min-resolution", 16), "--min-resolution must be"),
    (("--order", 3, "--self-order", 2), "--self-order must be"),
    (("--basis", "haar", "--bits", 6), "--bits must be 8 with --basis haar"),
    (("--basis", "haar", "--map", 24), "--map must be a power of two"),
])
def test_field_option_errors_name_the_option_not_the_mesh(run_cli, tmp_path, box, args,
                                                           named):
    out = tmp_path / "out.h5"
    code, stdout, err = run_cli("field", "sample", box, "-o", out, *args)
    assert code == 2 and stdout == "" and "Traceback" not in err
    assert err.startswith("error: ") and err.count("\n") == 1 and named in err, err
    assert "bunny.obj" not in err and "out.h5" not in err, err
    assert not out.exists()


@pytest.mark.parametrize(("args", "named"), [
    (("--function", "cone", "--alpha", 95), "'--alpha': 95.0 is not in the range 0<x<90"),
    (("--function", "cone", "--k-range", 2, 1), "--k-range 2 1 is inverted"),
    (("--function", "cone", "--k-range", 2, 8), "0 < lo < 1 < hi"),
    # in range as degrees but 0 in radians: refused as the option, not an internal error
    (("--function", "cone", "--alpha", "5e-324"), "--alpha 4.94066e-324: cone half-angle"),
    (("--function", "cone", "--k-range", "5e-324", 2), "hi / lo finite"),
])
def test_scaling_option_errors_name_the_option_not_the_output(run_cli, tmp_path, args,
                                                               named):
    out = tmp_path / "s2.h5"
    code, stdout, err = run_cli("tables", "scaling", "-n", 2, *args, "-o", out)
    assert code == 2 and stdout == "" and "Traceback" not in err
    assert err.startswith("error: ") and err.count("\n") == 1 and named in err, err
    assert "s2.h5" not in err, err
    assert not out.exists()


def test_log_plot_order_error_names_the_option(run_cli, tmp_path):
    out, plot = tmp_path / "t.h5", tmp_path / "p.png"
    code, _, err = run_cli("tables", "log", "-n", 1, "--plot", plot, "-o", out)
    assert code == 2 and "--order 1" in err and "p.png" not in err, err
    assert not out.exists() and not plot.exists()
