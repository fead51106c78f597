"""bench_look --set: this tree's bakes take the given [settings], in a copy of the scene
file beside it (its relative asset paths hold), the original untouched."""

from __future__ import annotations

from benchmarks import bench_look

SCENE = """# a scene
[settings]
order = 4
traced_shadow_directions = 96

[environment]
coeffs = [{coeffs}]

[[objects]]
name = "ground"
primitive = { type = "plane", size = [2.0, 2.0], subdivisions = 4 }
role = "receiver"
""".replace("{coeffs}", ", ".join(["[1, 1, 1]"] + ["[0, 0, 0]"] * 15))


def test_the_copy_carries_the_settings_and_loads(tmp_path):
    from shtools.scene.scene import load_scene

    path = tmp_path / "s.toml"
    path.write_text(SCENE)
    before = path.read_bytes()
    copy = bench_look.with_settings(path, ["traced_shadow_directions = 48",
                                           "self_visibility_directions = 64"])
    assert copy.parent == path.parent and copy != path
    assert path.read_bytes() == before
    settings = load_scene(copy).settings
    # a key the file had is replaced (a TOML table cannot repeat a key), a new one added
    assert settings.traced_shadow_directions == 48
    assert settings.self_visibility_directions == 64
    assert settings.order == 4


def test_a_file_without_a_settings_table_gets_one(tmp_path):
    from shtools.scene.scene import load_scene

    path = tmp_path / "s.toml"
    path.write_text(SCENE.replace("order = 4\ntraced_shadow_directions = 96\n", "")
                    .replace("[settings]\n", ""))
    copy = bench_look.with_settings(path, ["traced_shadow_directions = 48"])
    assert load_scene(copy).settings.traced_shadow_directions == 48


def test_headers_with_comments_quoted_and_repeated_keys(tmp_path):
    from shtools.scene.scene import load_scene

    path = tmp_path / "s.toml"
    path.write_text(SCENE.replace("[settings]\n", "[ settings ]  # the bake\n")
                    .replace("traced_shadow_directions = 96",
                             '"traced_shadow_directions" = 96  # rays'))
    copy = bench_look.with_settings(path, ["traced_shadow_directions = 48",
                                           "traced_shadow_directions = 24"])
    assert load_scene(copy).settings.traced_shadow_directions == 24  # the last one wins


def test_a_setting_the_toml_cannot_take_is_refused_before_any_bake(tmp_path):
    import pytest

    path = tmp_path / "s.toml"
    path.write_text(SCENE)
    for bad in (["traced shadow = 3"], ["order = four"]):
        with pytest.raises(ValueError, match="--set"):
            bench_look.with_settings(path, bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]  # no copy left


def test_an_existing_file_of_the_copys_name_is_never_written_over(tmp_path):
    import pytest

    path = tmp_path / "s.toml"
    path.write_text(SCENE)
    copy = bench_look.with_settings(path, ["traced_shadow_directions = 48"])
    copy.write_text("mine")  # a user's file (or a copy a stopped run left)
    with pytest.raises(ValueError, match="exists"):
        bench_look.with_settings(path, ["traced_shadow_directions = 48"])
    assert copy.read_text() == "mine"
