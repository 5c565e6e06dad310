"""The options objects (sns_np.options): one default per option, checks, the resume key, the
metadata round trip and the command-line flags built from them."""

import argparse
import dataclasses
import json

import pytest

from sns_np.cli import FIT_FLAGS, build_parser
from sns_np.options import (
    FitOptions,
    HeatOptions,
    MCFOptions,
    UnknownOptionError,
    add_arguments,
    given_arguments,
)

ALL = (FitOptions, HeatOptions, MCFOptions)


@pytest.mark.parametrize("options", ALL)
def test_every_field_has_help_and_a_check_and_the_defaults_pass_it(options):
    o = options()                                       # the defaults are valid
    for f in dataclasses.fields(options):
        assert f.metadata["help"] and not f.metadata["help"].endswith(".")
        assert callable(f.metadata["check"])
    assert options.from_dict(o.to_dict()) == o
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.lr = 1.0


def test_the_old_default_dicts_are_read_from_the_dataclasses():
    from sns_np.flows import HEAT_DEFAULTS, MCF_DEFAULTS
    from sns_np.surface import DEFAULTS
    assert DEFAULTS == FitOptions().to_dict()
    assert HEAT_DEFAULTS == HeatOptions().to_dict()
    assert MCF_DEFAULTS == MCFOptions().to_dict()


@pytest.mark.parametrize("options, kwargs, words", [
    (FitOptions, {"steps": 0}, "steps must be an integer >= 1, got 0"),
    (FitOptions, {"depth": -1}, "depth must be an integer >= 0"),
    (FitOptions, {"lr": -1.0}, "lr must be finite and > 0"),
    (FitOptions, {"normal_weight": float("nan")}, "normal_weight must be finite and >= 0"),
    (FitOptions, {"optimizer": "lbfgs"}, "unknown optimizer 'lbfgs'"),
    (FitOptions, {"width": 2.5}, "width must be an integer"),
    (HeatOptions, {"growth": 1.0}, "growth must be > 1"),
    (HeatOptions, {"n_points": 8}, "n_points must be an integer >= 16"),
    (HeatOptions, {"eigen_options": 3}, "eigen_options must be a dict"),
    (MCFOptions, {"dtype": "float16"}, "unknown dtype 'float16'"),
    (MCFOptions, {"refit_steps": -1}, "refit_steps must be an integer >= 0"),
])
def test_bad_values_name_the_option_and_what_was_expected(options, kwargs, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(")):
        options.from_kwargs(**kwargs)


def test_unknown_names_are_refused_with_the_valid_ones():
    with pytest.raises(UnknownOptionError, match="unknown fitting option.*'widht'.*width"):
        FitOptions.from_kwargs(widht=3)
    with pytest.raises(TypeError):                     # as an unexpected keyword argument
        FitOptions.from_kwargs(widht=3)
    with pytest.raises(ValueError, match="unknown option.*'n_point'.*heat_flow.*n_points"):
        HeatOptions.from_kwargs(n_point=3)
    o, rest = FitOptions.split({"width": 8, "checkpoint": "c.npz", "lr": None},
                               extra=("checkpoint",))
    assert (o.width, o.lr, rest) == (8, None, {"checkpoint": "c.npz"})


def test_values_are_kept_as_given():
    # the metadata and the resume key of a model keep what the user passed (an int stays an
    # int), so that checkpoints written before the options objects still resume
    o = FitOptions(normal_weight=0, lr=1)
    assert json.dumps(o.to_dict()["normal_weight"]) == "0"
    assert o.resume_key()["lr"] == 1 and isinstance(o.resume_key()["lr"], int)


def test_the_fit_resume_key_adds_the_target_to_the_options_key():
    import numpy as np

    from sns_np.shapes import Ellipsoid
    from sns_np.surface.fit import _resume_key, _ShapeTarget
    key = json.loads(_resume_key(_ShapeTarget(Ellipsoid(1.0, 1.3, 0.7)),
                                 FitOptions(seed=np.random.default_rng(1)), None))
    assert key["seed"] == "generator" and key["smooth"] is None and key["warm_start"] is None
    assert set(key) == set(FitOptions().resume_key()) | {"smooth", "target", "warm_start"}
    assert "time_budget" not in key and "n_eval" not in key and "tol" not in key


def _subparser(*path):
    p = build_parser()
    for name in path:
        p = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction)).choices[name]
    return p


@pytest.mark.parametrize("path, options, names", [
    (("fit",), FitOptions, FIT_FLAGS),
    (("demo",), FitOptions, FIT_FLAGS),
    (("batch", "fit"), FitOptions, FIT_FLAGS),
    (("heat",), HeatOptions, ("n_points", "refit_steps", "k")),
    (("mcf",), MCFOptions, ("n_points", "refit_steps", "lr")),
])
def test_command_line_options_come_from_the_dataclass(path, options, names):
    p = _subparser(*path)
    text = " ".join(p.format_help().split())
    for name in names:
        action = next(a for a in p._actions if a.dest == name)
        assert action.default is None                  # the library applies the default
        f = options.field(name)
        help_text = " ".join(f.metadata["help"].split())
        assert help_text in text
        if f.default is not None:
            assert f"{help_text} (default: {f.default})" in text


def test_add_arguments_checks_as_the_library_does():
    p = argparse.ArgumentParser(prog="x", exit_on_error=False)
    add_arguments(p, MCFOptions, ["n_points", "dtype"], flags={"n_points": "--points"})
    assert given_arguments(p.parse_args(["--points", "64"]), ["n_points", "dtype"]) == \
        {"n_points": 64}
    with pytest.raises(argparse.ArgumentError, match="n_points must be an integer >= 16"):
        p.parse_args(["--points", "8"])
    with pytest.raises(argparse.ArgumentError, match="expected an integer, got 'many'"):
        p.parse_args(["--points", "many"])


def test_second_moment_decay_flag_says_who_takes_it_and_checks_as_the_library_does():
    """``sns-np fit --second-moment-decay``: the help names both optimisers that have a second
    moment and the defaults "auto" takes from SECOND_MOMENT_DECAY; the value is parsed and
    refused as FitOptions does."""
    from sns_np.options import SECOND_MOMENT_DECAY
    p = _subparser("fit")
    text = " ".join(p.format_help().split())
    assert "--second-moment-decay" in text
    help_text = " ".join(FitOptions.help("second_moment_decay").split())
    assert "Adam and SOAP" in help_text and "Adam's own 0.999" in help_text
    assert f"{SECOND_MOMENT_DECAY['embedding']:g} for a mesh" in help_text
    assert f"{SECOND_MOMENT_DECAY['exact']:g} for an analytic map" in help_text
    args = p.parse_args(["mesh.obj", "-o", "m.npz", "--second-moment-decay", "0.9"])
    assert given_arguments(args, ["second_moment_decay"]) == {"second_moment_decay": 0.9}
    q = argparse.ArgumentParser(prog="x", exit_on_error=False)
    add_arguments(q, FitOptions, ["second_moment_decay"])
    with pytest.raises(argparse.ArgumentError, match=r"second_moment_decay must lie in \[0, 1\)"):
        q.parse_args(["--second-moment-decay", "1"])
