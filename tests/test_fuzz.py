"""Property-based fuzzing of the public entry points (issue 20): whatever the input, the only
exceptions are the documented ones (ValueError, TypeError, their LipgenError subclasses, and
OSError for files), and what is returned is finite.

``make test`` runs a bounded profile (a few examples each, seconds in all); ``make fuzz`` runs
the long one (``HYPOTHESIS_PROFILE=fuzz``).
"""

import json
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

from lipgen import Physics, dofs  # noqa: E402
from lipgen.errors import LipgenError  # noqa: E402
from lipgen.mesh.lipmesh import LipMesh  # noqa: E402
from lipgen.mesh.procedural import lip_mesh  # noqa: E402

settings.register_profile("bounded", max_examples=12, deadline=None, derandomize=True,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
settings.register_profile("fuzz", max_examples=400, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "bounded"))

ALLOWED = (ValueError, TypeError, LipgenError)
FILE_ALLOWED = (*ALLOWED, OSError)

floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
small_floats = st.floats(-1e3, 1e3)


ANY_SHAPE = hnp.array_shapes(min_dims=0, max_dims=3, max_side=6)


def arrays(shape=ANY_SHAPE, elements=floats):
    return hnp.arrays(np.float64, shape, elements=elements)


@pytest.fixture(scope="module")
def lips():
    return lip_mesh(0)


@pytest.fixture(scope="module")
def physics(lips):
    return Physics(lips)


# ---- mesh loaders --------------------------------------------------------------------------

_OBJ_LINES = st.one_of(
    st.builds(lambda a, b, c: f"v {a} {b} {c}", small_floats, small_floats, small_floats),
    st.builds(lambda a, b, c: f"f {a} {b} {c}", *(st.integers(-3, 12),) * 3),
    st.sampled_from(["", "# c", "vt 0 0", "o x", "f 1/1 2/2 3/3", "v nan 0 0", "v 1e309 0 0", "garbage"]))


@given(lines=st.lists(_OBJ_LINES, max_size=20), anchors=st.lists(st.integers(-2, 12), max_size=4))
def test_from_file_obj_raises_only_documented_errors(lines, anchors):
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "m.obj"
        p.write_text("\n".join(lines) + "\n")
        try:
            m = LipMesh.from_file(p, anchors=anchors)
        except FILE_ALLOWED:
            return
        assert np.isfinite(m.vertices).all() and m.faces.min() >= 0


_JSON = st.recursive(st.none() | st.booleans() | st.integers(-5, 300) | st.floats() | st.text(max_size=5),
                     lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=8), c, max_size=4),
                     max_leaves=12)


@given(edit=st.dictionaries(st.sampled_from(["kind", "schema", "anchors", "markers", "regions",
                                             "region_names", "nose", "n_nodes", "n_faces"]), _JSON,
                            max_size=3), whole=st.one_of(st.none(), _JSON))
def test_read_mesh_sidecar_raises_only_documented_errors(lips, edit, whole):
    from lipgen.mesh.io import read_mesh, write_mesh

    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "m.obj"
        write_mesh(lips, p)
        side = Path(tmp) / "m.obj.json"
        meta = json.loads(side.read_text())
        side.write_text(json.dumps(whole if whole is not None else {**meta, **edit}))
        try:
            m = read_mesh(p)
        except FILE_ALLOWED:
            return
        assert m.n_nodes == lips.n_nodes


# ---- Physics and reach ---------------------------------------------------------------------

@given(V=arrays(hnp.array_shapes(min_dims=2, max_dims=2, min_side=1, max_side=8), small_floats),
       F=hnp.arrays(np.int64, hnp.array_shapes(min_dims=2, max_dims=2, max_side=6),
                    elements=st.integers(-1, 8)),
       anchors=st.lists(st.integers(-1, 8), max_size=4))
def test_physics_of_any_mesh_raises_only_documented_errors(V, F, anchors):
    try:
        ph = Physics(LipMesh(V, F, None, anchors))
    except ALLOWED:
        return
    U = ph.displace(np.ones((ph.n_nodes, 3)))
    assert np.isfinite(U).all()


@given(nodes=st.lists(st.integers(-5, 210), min_size=0, max_size=6),
       axes=st.sampled_from(["xyz", "x", "yz", "", "q"]), values=arrays())
def test_reach_raises_only_documented_errors(physics, nodes, axes, values):
    for objective in ("force", "energy"):
        try:
            d = dofs(nodes, axes, n_nodes=physics.n_nodes)
            U, F = physics.reach(d, values, objective=objective)
        except ALLOWED:
            continue
        goals = np.reshape(values, (-1, len(d)))
        scale = max(1.0, float(np.abs(goals).max()))  # linear: the error scales with the goals
        assert np.isfinite(U).all()
        assert np.abs(U.reshape(-1, physics.n_dofs)[:, d] - goals).max() <= 1e-9 * scale


# ---- modes and LLSE ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def model(lips, physics):
    from lipgen.modes.model import ModeModel

    rng = np.random.default_rng(0)
    return ModeModel(n_modes=4).fit_from_markers(physics, rng.normal(scale=2.0, size=(12, 16, 3)))


@given(nodes=st.lists(st.integers(-3, 205), max_size=5), values=arrays(), noise=floats,
       n_modes=st.one_of(st.integers(-1, 6), st.sampled_from(["full", "x", None])))
def test_llse_raises_only_documented_errors(model, nodes, values, noise, n_modes):
    try:
        est = model.llse(dofs(nodes, n_nodes=model.n_nodes_), n_modes=n_modes, noise=noise)
        out = est.estimate(values)
    except ALLOWED:
        return
    assert np.isfinite(out).all()


# ---- nrsfm ---------------------------------------------------------------------------------

@given(W=arrays(hnp.array_shapes(min_dims=1, max_dims=3, max_side=8), st.floats(-50, 50) | floats),
       k=st.integers(-1, 4), method=st.sampled_from(["dai", "bregler", "em-ppca", "nope"]))
def test_nrsfm_reconstruct_raises_only_documented_errors(W, k, method):
    from lipgen.nrsfm import reconstruct

    try:
        rec = reconstruct(W, k, method=method, n_starts=1, shape_starts=1, refine_iter=5, em_iter=5)
    except ALLOWED:
        return
    assert np.isfinite(rec.S).all()


# ---- USD export ----------------------------------------------------------------------------

@given(weights=st.one_of(st.none(), arrays()), points=st.one_of(st.none(), arrays()),
       fps=floats, weight_range=st.sampled_from(["signed", "unit", "x"]), start=st.integers(-3, 3))
def test_export_usd_raises_only_documented_errors(lips, model, weights, points, fps, weight_range, start):
    pytest.importorskip("pxr")
    from lipgen.usd.export import export_usd

    with tempfile.TemporaryDirectory() as tmp:
        try:
            out = export_usd(Path(tmp) / "x.usda", lips, model if weights is not None else None, weights,
                             points, fps=fps, weight_range=weight_range, start=start)
        except ALLOWED:
            assert not (Path(tmp) / "x.usda").exists()
            return
        assert "inf" not in out.read_text().replace("info", "")


# ---- the manifest reader -------------------------------------------------------------------

@pytest.fixture(scope="module")
def manifest(lips):
    from lipgen.dataset.layout import GenerateSettings, build_manifest
    from lipgen.rig.camera import default_rig

    s = GenerateSettings(frames=2, calib_frames=1, size=(160, 120))
    return build_manifest(s, default_rig(160, 120), lips, ["a"], "0")


_PATHS = st.sampled_from(["raw/000000.png", "../x.png", "/etc/passwd", "raw/../../x", "C:\\x", "~/x", "",
                          "raw/000001.png"])


@given(key=st.sampled_from(["frames", "fps", "settings", "mesh", "marks", "calibration", "rig", "views",
                            "format", "schema_version", "units"]), value=_JSON | _PATHS,
       frame_key=st.sampled_from(["raw", "truth", "time", "index", "depth"]), frame_value=_JSON | _PATHS)
def test_manifest_reader_raises_only_dataset_errors(manifest, key, value, frame_key, frame_value):
    from lipgen.dataset.layout import Dataset, validate_manifest
    from lipgen.errors import DatasetError

    m = json.loads(json.dumps(manifest))
    m["frames"][1][frame_key] = frame_value
    for mm in (m, {**m, key: value}):
        try:
            validate_manifest(mm)
        except DatasetError:
            continue
        for f in mm["frames"]:  # accepted: every path stays inside
            for k in ("raw", "truth", "depth"):
                if k in f:
                    assert not f[k].startswith(("/", "~")) and ".." not in Path(f[k]).parts
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "manifest.json").write_text(json.dumps({**m, key: value}))
        try:
            ds = Dataset(tmp)
            ds.missing()
        except (DatasetError, IndexError):  # IndexError: Dataset[i] out of range is documented
            return


# ---- the CLI parsers -----------------------------------------------------------------------

_TOKENS = st.sampled_from(["generate", "show", "train", "evaluate", "nrsfm", "mesh", "export-usd",
                           "reconstruct", "bench", "experiment", "--out", "--force", "--k", "auto", "0",
                           "-1", "nan", "1e309", "x.npz", "--frames", "--size", "16x12", "--resume",
                           "--weights", "--fps", "--model", "--help", "--version", "", "--", "table51",
                           "--mesh", "-r", "99"])


@given(argv=st.lists(_TOKENS, max_size=7))
def test_cli_parsers_exit_cleanly(argv):
    from lipgen.cli import build_parser

    try:
        build_parser().parse_args(argv)
    except SystemExit as exc:
        assert exc.code in (0, 2)


@given(k=st.sampled_from(["auto", "3", "0", "-1", "x", "nan"]),
       opts=st.lists(st.sampled_from(["--kmax", "0", "-2", "--rtol", "nan", "-1", "0.5", "--method", "dai",
                                      "em-ppca", "--seed", "x", "3"]), max_size=6),
       W=arrays(hnp.array_shapes(min_dims=0, max_dims=3, max_side=6)))
def test_nrsfm_command_never_tracebacks(k, opts, W, capsys):
    from lipgen.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        np.savez(Path(tmp) / "t.npz", W=W)
        try:
            argv = ["nrsfm", str(Path(tmp) / "t.npz"), "--k", k, *opts, "--out", str(Path(tmp) / "s.npz")]
            code = main(argv)
        except SystemExit as exc:
            code = exc.code
        assert code in (0, 1, 2)
    assert "Traceback" not in capsys.readouterr().err
