"""Crafted model files (issue 13): bounded cost, one-line ModelFileErrors naming file and field.

Every crafted file is refused by ``SphericalNeuralSurface.load`` with a :class:`ModelFileError`
whose message names the file (and the field), in well under a second and without allocating
more than the file's honest size (measured with tracemalloc, which sees NumPy's buffers); and
``sns-np info|eval|eigen|heat|mcf`` report it as one line with exit status 2.
"""

import io
import json
import time
import tracemalloc
import zipfile

import numpy as np
import pytest

from sns_np.errors import ModelFileError
from sns_np.fields import NeuralField
from sns_np.nn import ResidualMLP
from sns_np.surface import SphericalNeuralSurface

from .conftest import run_cli

MB = 1 << 20


def _model(width=8, depth=1, metadata=None):
    return SphericalNeuralSurface(ResidualMLP(width=width, depth=depth, seed=0),
                                  center=[0.5, 0.0, -1.0], scale=2.0,
                                  metadata={"source": "test"} if metadata is None else metadata)


def _npy(a):
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asarray(a), allow_pickle=True)
    return buf.getvalue()


def _write_zip(path, members, compression=zipfile.ZIP_STORED):
    """members: name -> bytes (an .npy image) or np array."""
    with zipfile.ZipFile(path, "w", compression=compression) as zf:
        for name, data in members.items():
            zf.writestr(name + ".npy", data if isinstance(data, bytes) else _npy(data))
    return path


def _state(**changes):
    state = _model().state()
    state.update(changes)
    return {k: v for k, v in state.items() if v is not None}


def _header_only(shape, dtype="<f8"):
    """An .npy header declaring ``shape`` with none of its data."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": dtype, "fortran_order": False, "shape": tuple(shape)})
    return buf.getvalue()


def _refused(path, *words):
    """Load ``path``; assert a one-line ModelFileError naming it (and ``words``), in < 1 s and
    < 100 MB of allocations beyond the file's size. Returns the message."""
    size = path.stat().st_size
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(ModelFileError) as info:
            SphericalNeuralSurface.load(path)
        seconds = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    msg = str(info.value)
    assert str(path) in msg and "\n" not in msg, msg
    for w in words:
        assert w in msg, msg
    assert seconds < 1.0, (seconds, msg)
    assert peak < size + 100 * MB, (peak, msg)
    return msg


# ------------------------------------------------------------------ sizes before allocation

def test_huge_declared_width_is_refused_before_allocating(tmp_path):
    # the file: width 2000 declared (64 M parameters, 512 MB), a small theta stored
    path = _write_zip(tmp_path / "wide.npz", _state(**{"net.width": np.array(2000),
                                                       "net.depth": np.array(8)}))
    _refused(path, "'net.theta'", "(the parameter vector)", "needs (64012000,)")
    # width 11000 with a theta header that agrees but holds no data
    n = ResidualMLP.count_params(3, 3, 11000, 8)
    path = _write_zip(tmp_path / "wider.npz", _state(**{
        "net.width": np.array(11000), "net.depth": np.array(8),
        "net.theta": _header_only((n,))}))
    _refused(path, "'net.theta'", f"declares shape ({n},)", "its archive member holds 0")
    # an absurd width (exact integer arithmetic, no overflow)
    path = _write_zip(tmp_path / "absurd.npz", _state(**{"net.width": np.array(2**62)}))
    _refused(path, "'net.theta'")


def test_zip_bomb_is_refused_from_the_directory(tmp_path):
    # a consistent width-2000 model whose 512 MB of zeros deflate to about 0.5 MB
    n = ResidualMLP.count_params(3, 3, 2000, 8)
    members = {k: _npy(v) for k, v in _state(**{"net.width": np.array(2000),
                                                 "net.depth": np.array(8)}).items()
               if k != "net.theta"}
    path = tmp_path / "bomb.npz"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for k, v in members.items():
            zf.writestr(k + ".npy", v)
        with zf.open("net.theta.npy", "w", force_zip64=True) as fh:
            fh.write(_header_only((n,)))
            zero = bytes(16 * MB)
            for _ in range(n * 8 // len(zero)):
                fh.write(zero)
            fh.write(bytes(n * 8 % len(zero)))
    assert path.stat().st_size < 2 * MB
    _refused(path, "unpack to", "zip bomb")


def test_lying_member_sizes_are_refused(tmp_path):
    # the central directory claims a huge uncompressed size for a tiny stored member
    path = _write_zip(tmp_path / "liar.npz", _state())
    raw = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("net.theta.npy")
    # patch the uncompressed size in its central directory record (the last mention of the
    # name; the record starts 46 bytes before it, the size is at offset 24)
    pos = raw.rfind(b"net.theta.npy") - 46
    assert raw[pos:pos + 4] == b"PK\x01\x02"
    raw[pos + 24:pos + 28] = (0xFFFF0000).to_bytes(4, "little")
    path.write_bytes(bytes(raw))
    assert info.file_size < 0xFFFF0000
    _refused(path)


# ------------------------------------------------------------------ fields named

@pytest.mark.parametrize("name, changes, words", [
    ("version_text", {"format_version": np.array("one")}, ["'format_version'", "integer"]),
    ("version_float", {"format_version": np.array(1.0)}, ["'format_version'"]),
    ("net_version", {"net.format_version": np.array([1, 1])}, ["'net.format_version'"]),
    ("width_text", {"net.width": np.array("wide")}, ["'net.width'"]),
    ("width_zero", {"net.width": np.array(0)}, ["'net.width'", ">= 1"]),
    ("depth_negative", {"net.depth": np.array(-1)}, ["'net.depth'"]),
    ("bias_int", {"net.bias": np.array(3)}, ["'net.bias'"]),
    ("dtype_odd", {"net.dtype": np.array("complex128")}, ["'net.dtype'"]),
    ("theta_nan", {"net.theta": np.full(ResidualMLP.count_params(3, 3, 8, 1), np.nan)},
     ["'net.theta'", "non-finite"]),
    ("theta_2d", {"net.theta": np.zeros((4, 4))}, ["'net.theta'"]),
    ("theta_missing", {"net.theta": None}, ["'net.theta'"]),
    ("center_short", {"center": np.zeros(2)}, ["'center'"]),
    ("scale_text", {"scale": np.array("big")}, ["'scale'"]),
    ("scale_zero", {"scale": np.array(0.0)}, ["scale"]),
    ("format_array", {"format": np.zeros(3)}, ["'format'"]),
    ("pickled", {"metadata": np.array([{}], dtype=object)}, ["'metadata'", "never unpickled"]),
    ("metadata_list", {"metadata": np.array("[1, 2]")}, ["'metadata'", "JSON object"]),
    ("metadata_bad_json", {"metadata": np.array("{")}, ["'metadata'", "not valid JSON"]),
    ("deep", {"metadata": np.array("[" * 100000 + "]" * 100000)}, ["'metadata'", "deeply"]),
    ("deep_object", {"metadata": np.array('{"a":' * 70 + "1" + "}" * 70)}, ["deeply"]),
    ("fit_list", {"metadata": np.array('{"fit": [1, 2]}')}, ["'metadata.fit'"]),
    ("fit_text", {"metadata": np.array('{"fit": "yes"}')}, ["'metadata.fit'"]),
    ("fit_number_text", {"metadata": np.array(json.dumps({"fit": {
        "steps": 5, "seconds": 1.0, "position_mean": "small", "position_relative": 0.1,
        "normal_mean_deg": 1.0}}))}, ["'metadata.fit.position_mean'"]),
    ("fit_missing", {"metadata": np.array('{"fit": {"steps": 5}}')}, ["'metadata.fit.seconds'"]),
    ("fit_options", {"metadata": np.array(json.dumps({"fit": {
        "steps": 5, "seconds": 1.0, "position_mean": 0.1, "position_relative": 0.1,
        "normal_mean_deg": 1.0, "options": [1]}}))}, ["'metadata.fit.options'"]),
])
def test_crafted_fields_are_named(tmp_path, name, changes, words):
    path = _write_zip(tmp_path / f"{name}.npz", _state(**changes))
    _refused(path, *words)


def test_checkpoint_generator_state_is_checked(tmp_path):
    good = {"bit_generator": "PCG64", "state": {"state": 1, "inc": 3}, "has_uint32": 0,
            "uinteger": 0}
    base = _state(**{"checkpoint.key": np.array("k"), "checkpoint.step": np.array(3),
                     "checkpoint.seconds": np.array(1.5), "checkpoint.rng": np.array(
                         json.dumps(good)), "opt.kind": np.array("Adam"), "opt.t": np.array(3)})
    path = _write_zip(tmp_path / "ok.ckpt.npz", base)
    SphericalNeuralSurface.load(path)
    for name, rng, words in [
            ("list", [1, 2], ["'checkpoint.rng'", "not a random generator state"]),
            ("name", {"bit_generator": "os.system"}, ["'checkpoint.rng'"]),
            ("types", dict(good, state={"state": "x", "inc": [1]}), ["not a valid PCG64"]),
            ("missing", {"bit_generator": "PCG64"}, ["not a valid PCG64"])]:
        path = _write_zip(tmp_path / f"{name}.ckpt.npz",
                          dict(base, **{"checkpoint.rng": np.array(json.dumps(rng))}))
        _refused(path, *words)
    for name, changes, words in [
            ("step", {"checkpoint.step": np.array([1, 2])}, ["'checkpoint.step'"]),
            ("seconds", {"checkpoint.seconds": np.array(np.inf)}, ["'checkpoint.seconds'"]),
            ("opt_t", {"opt.t": np.array("3")}, ["'opt.t'"]),
            ("opt_m", {"opt.m": np.zeros(5)}, ["'opt.m'", "vector of"]),
            ("opt_kind", {"opt.kind": np.array("Nadam")}, ["'opt.kind'", "unknown optimiser"]),
            ("opt_case", {"opt.kind": np.array("adam")}, ["'opt.kind'", "class name 'Adam'"]),
            ("soap_flat", {"opt.kind": np.array("SOAP"), "opt.QL0": np.zeros((4, 4))},
             ["'opt.QL0'", "stack of matrices"]),
            ("soap_name", {"opt.kind": np.array("SOAP"), "opt.X0": np.zeros((1, 4, 4))},
             ["'opt.X0'", "not part of SOAP's state"]),
            ("history", {"checkpoint.history.loss": np.zeros((2, 2))},
             ["'checkpoint.history.loss'"])]:
        path = _write_zip(tmp_path / f"{name}.ckpt.npz", dict(base, **changes))
        _refused(path, *words)


def test_networks_and_fields_share_the_checks(tmp_path):
    net = ResidualMLP(width=8, depth=1, seed=0)
    state = net.state()
    state["width"] = np.array(5000)
    path = _write_zip(tmp_path / "net.npz", state)
    with pytest.raises(ModelFileError, match=r"net.npz: field 'theta' \(the parameter"):
        ResidualMLP.load(path)
    field = NeuralField(width=4, depth=1, seed=0)
    state = field.state()
    state["format_version"] = np.array("one")
    path = _write_zip(tmp_path / "field.npz", state)
    with pytest.raises(ModelFileError, match=r"field.npz: field 'format_version' must be an"):
        NeuralField.load(path)


def test_loading_draws_no_random_initialisation(tmp_path, monkeypatch):
    S = _model()
    path = S.save(tmp_path / "m.npz")

    def no_draw(self, seed=None):
        raise AssertionError("initialize() called while loading")
    monkeypatch.setattr(ResidualMLP, "initialize", no_draw)
    back = SphericalNeuralSurface.load(path)
    assert np.array_equal(back.net.theta, S.net.theta)
    assert np.array_equal(back.net.copy().theta, S.net.theta)
    assert np.array_equal(back.net.astype(np.float32).theta, S.net.theta.astype(np.float32))


def test_round_trip_of_fortran_and_compressed_files(tmp_path):
    S = _model()
    state = S.state()
    path = tmp_path / "c.npz"
    np.savez_compressed(path, **state)
    back = SphericalNeuralSurface.load(path)
    assert np.array_equal(back.net.theta, S.net.theta) and back.metadata == S.metadata


# ------------------------------------------------------------------ the command line

_cli = run_cli


def test_control_characters_are_not_printed_raw(tmp_path, capsys):
    path = _model(metadata={"source": "\x1b[31mred\x1b[0m\rline\n2", "\x07key": "x"}).save(
        tmp_path / "ctl.npz")
    code, out, err = _cli(["info", path], capsys)
    assert code == 0 and err == ""
    assert "\x1b" not in out and "\r" not in out and "\x07" not in out
    assert "\\x1b[31mred" in out and "\\x07key" in out
    assert len(out.splitlines()) == 5                      # model, network, transform, 2 keys


CRAFTED = {
    "deep": {"metadata": np.array("[" * 100000 + "]" * 100000)},
    "fit_list": {"metadata": np.array('{"fit": [1, 2]}')},
    "fit_partial": {"metadata": np.array('{"fit": {"steps": 5, "stopped": "x"}}')},
    "wide": {"net.width": np.array(11000)},
    "version": {"format_version": np.array("one")},
}


@pytest.mark.parametrize("command", ["info", "eval", "eigen", "heat", "mcf"])
@pytest.mark.parametrize("name", list(CRAFTED))
def test_commands_report_crafted_files_in_one_line(tmp_path, capsys, command, name):
    path = _write_zip(tmp_path / f"{name}.npz", _state(**CRAFTED[name]))
    extra = {"info": [], "eval": ["-o", tmp_path / "o.ply"], "eigen": ["-k", "2"],
             "heat": ["--field", "x", "--t-end", "0.1", "-o", tmp_path / "h"],
             "mcf": ["--t-end", "0.1", "-o", tmp_path / "m"]}[command]
    code, out, err = _cli([command, path, *extra], capsys)
    assert code == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"sns-np {command}: error: ")
    assert str(path) in lines[0]


def test_resume_from_a_crafted_checkpoint_is_one_line(tmp_path, capsys):
    from sns_np.mesh import write_mesh
    from sns_np.shapes import Ellipsoid
    V, F = Ellipsoid(1.0, 1.3, 0.7).mesh(1)
    mesh = tmp_path / "e.obj"
    write_mesh(mesh, V, F)
    out = tmp_path / "fit.npz"
    argv = ["fit", mesh, "-o", out, "--steps", "2", "--width", "8", "--depth", "1", "--quiet"]
    code, _, err = _cli(argv + ["--keep-checkpoint"], capsys)
    assert code == 0, err
    ckpt = tmp_path / "fit.ckpt.npz"
    with np.load(ckpt) as data:
        state = dict(data)
    state["checkpoint.rng"] = np.array(json.dumps({"bit_generator": "PCG64",
                                                   "state": {"state": [], "inc": None}}))
    np.savez(ckpt, **state)
    code, _, err = _cli(argv + ["--resume"], capsys)
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and str(ckpt) in lines[0] and "'checkpoint.rng'" in lines[0]


# ------------------------------------------------------------------ property-based
hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_KEYS = sorted(_model().state())
_ARRAYS = st.one_of(
    st.sampled_from([np.array(0), np.array(-1), np.array(2**40), np.array(1.5), np.array(np.nan),
                     np.array("one"), np.array(""), np.array(True), np.zeros(0), np.zeros(3),
                     np.zeros((2, 2)), np.array([1, 2]), np.array(["a", "b"]),
                     np.array("[" * 5000), np.array('{"fit": 1}'), np.array('{"fit": {}}'),
                     np.array(json.dumps({"x": "\x1b"})), np.zeros(3, dtype=">f8"),
                     np.zeros(5, dtype=np.complex128), np.zeros(2, dtype="i1,f4")]),
    st.integers(-2**63, 2**63 - 1).map(np.array),
    st.text(max_size=50).map(np.array))


def _assert_load_is_clean(path):
    t0 = time.perf_counter()
    try:
        SphericalNeuralSurface.load(path)
    except ModelFileError as exc:
        msg = str(exc)
        assert str(path) in msg and "\n" not in msg, msg
    assert time.perf_counter() - t0 < 1.0


_SETTINGS = settings(max_examples=80, deadline=None,
                     suppress_health_check=[HealthCheck.function_scoped_fixture])


@_SETTINGS
@given(changes=st.dictionaries(st.sampled_from(_KEYS), st.one_of(st.none(), _ARRAYS),
                               max_size=4))
def test_generated_fields_fail_cleanly(tmp_path, changes):
    state = _model().state()
    for k, v in changes.items():
        if v is None:
            state.pop(k, None)
        else:
            state[k] = v
    _assert_load_is_clean(_write_zip(tmp_path / "gen.npz", state))


@_SETTINGS
@given(cut=st.integers(0, 4000), flips=st.lists(st.tuples(st.integers(0, 10**6),
                                                          st.integers(1, 255)), max_size=6),
       junk=st.binary(max_size=64))
def test_generated_byte_damage_fails_cleanly(tmp_path, cut, flips, junk):
    raw = bytearray((_model().save(tmp_path / "src.npz")).read_bytes())
    for pos, x in flips:
        raw[pos % len(raw)] ^= x
    raw = raw[:len(raw) - cut] + junk if cut < len(raw) else bytearray(junk)
    path = tmp_path / "damaged.npz"
    path.write_bytes(bytes(raw))
    _assert_load_is_clean(path)


def test_files_that_are_not_archives(tmp_path):
    single = tmp_path / "single.npz"
    with open(single, "wb") as fh:
        np.save(fh, np.zeros(3))
    _refused(single, "a single .npy array?")
    text = tmp_path / "text.npz"
    text.write_text("v 0 0 0\n")
    _refused(text, "not a zip archive")
