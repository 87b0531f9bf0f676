import pytest

from photoservo.errors import InputError
from photoservo.cli.main import main
from photoservo.config import load_config
from photoservo.tomlconf import dump_config


def test_defaults_load_and_dump_round_trip(tmp_path):
    cfg = load_config()
    p = tmp_path / "c.toml"
    p.write_text(dump_config(cfg))
    # compared as text: nan (an unknown water height) is not equal to itself
    assert dump_config(load_config(p)) == dump_config(cfg)


def test_set_overrides_are_validated():
    cfg = load_config(overrides=["photo_model.band_px=7"])
    assert cfg.photo_model.band_px == 7.0
    with pytest.raises(InputError, match="unknown key 'photo_model.nope'"):
        load_config(overrides=["photo_model.nope=1"])
    with pytest.raises(InputError, match="photo_model.hue_tolerance': expected an integer"):
        load_config(overrides=["photo_model.hue_tolerance=1.5"])


def test_user_file_unknown_key(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text("[photo_model]\nbandpx = 3\n")
    with pytest.raises(InputError, match="unknown key 'photo_model.bandpx'"):
        load_config(p)


def test_cli_bad_key_exits_2_with_one_line(capsys):
    assert main(["config", "show", "--set", "photo_model.x=1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "photo_model.x" in err[0]


def _numeric_keys(doc: dict):
    for section, table in doc.items():
        for key, value in table.items():
            vals = value if isinstance(value, list) else [value]
            if any(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
                yield section, key, vals


def test_every_numeric_key_has_a_bound_that_holds_its_default():
    from photoservo.tomlconf import configs_dir, read_toml

    doc = read_toml(configs_dir() / "default.toml")
    bounds = read_toml(configs_dir() / "bounds.toml")
    keys = list(_numeric_keys(doc))
    assert len(keys) > 100
    for section, key, vals in keys:
        assert key in bounds.get(section, {}), f"configs/bounds.toml has no bound for {section}.{key}"
        lo, hi = bounds[section][key]
        assert lo <= hi
        for v in vals:
            assert v != v or lo <= v <= hi, f"default {section}.{key} = {v} outside [{lo}, {hi}]"
    for section, table in bounds.items():  # and no bound for a key that does not exist
        if isinstance(table, dict):
            assert set(table) <= set(doc[section]), f"bounds for unknown keys in [{section}]"


@pytest.mark.parametrize("override, words", [
    ("ga.population=1000000000000", ["ga.population", "1000000000000", "10000"]),  # was a MemoryError
    ("motion.tool_speed_max_mm_s=inf", ["motion.tool_speed_max_mm_s", "finite"]),  # would disable the cap
    ("motion.tool_speed_max_mm_s=nan", ["motion.tool_speed_max_mm_s", "finite"]),
    ("link.silence_timeout_s=-inf", ["link.silence_timeout_s", "finite"]),
    ("servo.max_speed_mm_s=1e9", ["servo.max_speed_mm_s", "2000"]),
    ("ga.bits=[10,10,10,10,9,9,64]", ["ga.bits", "64", "2..30"]),
    ("sim.water_z_mm=nan", ["sim.water_z_mm", "finite"]),
])
def test_out_of_bound_values_are_one_line_exit_2(capsys, override, words):
    assert main(["config", "show", "--set", override]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(w in err for w in words), err


def test_nan_means_unknown_only_where_documented():
    cfg = load_config(overrides=["tracker.water_z_mm=nan"])
    assert cfg.tracker.water_z_mm != cfg.tracker.water_z_mm
