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
