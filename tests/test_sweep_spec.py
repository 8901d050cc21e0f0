"""Sweep specs: how they expand into runs, and every way a spec can be wrong (one line naming the
key, exit status 2, nothing written). No compiler needed: a bad spec stops before the build."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from chaingen.studies.sweep import SweepError, chunk_size, parse_spec

from helpers import ROOT, chaingen_in_process

SCENE = str(ROOT / "scenes" / "three_link_mono.toml")


def spec(**entries):
    document = {"scene": SCENE, "axes": {"springs[0].stiffness": [5.0, 10.0]}}
    document.update(entries)
    return parse_spec(document)


def test_product_expands_first_axis_slowest():
    found = spec(axes={"springs[0].stiffness": [1.0, 2.0, 3.0],
                       "links[1].mass": {"from": 0.5, "to": 2.0, "num": 4}})
    assert len(found.runs) == 12
    assert [run["springs[0].stiffness"] for run in found.runs[:5]] == [1.0] * 4 + [2.0]
    assert [run["links[1].mass"] for run in found.runs[:4]] == [0.5, 1.0, 1.5, 2.0]
    assert found.parameters == ("springs[0].stiffness", "links[1].mass")


def test_a_spec_built_with_numpy_reads_as_the_plain_one():
    """numpy scalars and arrays, and tuples, read as the numbers and lists they hold (before,
    t_end = np.float32(0.5) was refused as 'must be > 0 and finite', an axis given as an array
    as 'a list or a range', and the digest took numpy's str())."""
    plain = spec(t_end=0.5, every=2, seed=3,
                 axes={"springs[0].stiffness": [5.0, 10.0],
                       "links[1].mass": {"from": 0.5, "to": 2.0, "num": 4}})
    mixed = spec(t_end=np.float32(0.5), every=np.int64(2), seed=np.uint8(3),
                 axes={"springs[0].stiffness": np.array([5.0, 10.0]),
                       "links[1].mass": {"from": np.float64(0.5), "to": np.float32(2.0),
                                         "num": np.int32(4)}})
    assert mixed.runs == plain.runs and mixed.digest == plain.digest
    assert (mixed.t_end, mixed.every, mixed.seed) == (plain.t_end, plain.every, plain.seed)
    assert spec(axes={"springs[0].stiffness": (5.0, 10.0)}).runs == spec().runs
    with pytest.raises(SweepError, match="every: must be an integer"):
        spec(every=np.True_)


def test_a_spec_that_is_no_table_is_refused():
    with pytest.raises(SweepError, match=r"<sweep>: a sweep spec is a table .* got list"):
        parse_spec([{"scene": SCENE}])
    from chaingen import sweep

    with pytest.raises(TypeError, match="sweep: spec must be .* got list"):
        sweep([{"scene": SCENE}])


def test_run_time_axes_are_not_parameters():
    found = spec(axes={"initial.angles[0]": [0.1, 0.2], "simulation.dt": [0.01, 0.005],
                       "links[0].mass": [1.0, 1.5]})
    assert found.parameters == ("links[0].mass",)
    assert len(found.runs) == 8
    assert found.n_steps({"simulation.dt": 0.005}) == round(found.t_end / 0.005)


def test_adaptive_tolerances_come_from_the_spec_or_the_scene():
    """rtol/atol: the spec's keys, else the scene's simulation.rtol/atol (fixed steps when both
    are 0); every run then takes them as its Newton options."""
    assert spec().options is None
    adaptive = spec(rtol=1e-8, atol=1e-9)
    assert (adaptive.rtol, adaptive.atol) == (1e-8, 1e-9)
    assert adaptive.options == {"rtol": 1e-8, "atol": 1e-9}
    assert adaptive.digest != spec().digest


def test_a_scene_s_adaptive_tolerances_reach_the_sweep(tmp_path):
    scene = tmp_path / "adaptive.toml"
    scene.write_text((ROOT / "scenes" / "three_link_mono.toml").read_text().replace(
        "[simulation]", "[simulation]\nrtol = 1e-7\natol = 1e-7"))
    found = parse_spec({"scene": str(scene), "axes": {"springs[0].stiffness": [5.0]}})
    assert found.options == {"rtol": 1e-7, "atol": 1e-7}
    assert parse_spec({"scene": str(scene), "rtol": 0.0, "atol": 0.0,
                       "axes": {"springs[0].stiffness": [5.0]}}).options is None


def test_zip_pairs_values():
    found = spec(mode="zip", axes={"springs[0].stiffness": [1.0, 2.0, 3.0],
                                   "links[1].mass": [0.5, 0.6, 0.7]})
    assert [(run["springs[0].stiffness"], run["links[1].mass"]) for run in found.runs] == \
        [(1.0, 0.5), (2.0, 0.6), (3.0, 0.7)]


def test_log_spacing():
    found = spec(axes={"springs[0].stiffness": {"from": 1.0, "to": 100.0, "num": 3,
                                                "spacing": "log"}})
    assert [run["springs[0].stiffness"] for run in found.runs] == pytest.approx([1, 10, 100])


@pytest.mark.parametrize("sampler", ["sobol", "latin-hypercube"])
def test_samples_are_seeded_and_in_range(sampler):
    axes = {"springs[0].stiffness": {"from": 2.0, "to": 8.0},
            "links[1].mass": {"from": 0.1, "to": 10.0, "spacing": "log"}}
    first = spec(mode="sample", samples=64, sampler=sampler, seed=3, axes=axes)
    again = spec(mode="sample", samples=64, sampler=sampler, seed=3, axes=axes)
    other = spec(mode="sample", samples=64, sampler=sampler, seed=4, axes=axes)
    assert first.runs == again.runs and first.runs != other.runs
    assert len(first.runs) == 64
    stiffness = [run["springs[0].stiffness"] for run in first.runs]
    mass = [run["links[1].mass"] for run in first.runs]
    assert 2.0 <= min(stiffness) and max(stiffness) <= 8.0
    assert 0.1 <= min(mass) and max(mass) <= 10.0
    # log spacing: as many draws below the geometric mean as above it, roughly
    assert 20 <= sum(value < 1.0 for value in mass) <= 44


def test_the_digest_follows_the_runs():
    assert spec().digest == spec().digest
    assert spec().digest != spec(axes={"springs[0].stiffness": [5.0, 11.0]}).digest
    assert spec().digest != spec(every=5).digest


def test_chunks_are_fixed_by_the_run_count():
    assert chunk_size(1) == 1
    assert chunk_size(1000) == 25
    assert chunk_size(10 ** 6) == 64


#: (spec document changes, the key the message must name, a word of the reason)
BAD_SPECS = {
    "unknown key": ({"colour": "red"}, "colour", "unknown key"),
    "unknown range key": ({"axes": {"links[0].mass": {"from": 1, "to": 2, "nmu": 3}}},
                          "nmu", "unknown key"),
    "no number": ({"axes": {"links[0].weight": [1.0]}}, "links[0].weight", "names no number"),
    "beyond the chain": ({"axes": {"links[3].mass": [1.0]}}, "links[3]", "does not exist"),
    "structure": ({"axes": {"springs[0].joints[1]": [2.0, 3.0]}}, "springs[0].joints",
                  "structure"),
    "actuation": ({"axes": {"actuation.joints": [1.0]}}, "actuation.joints", "structure"),
    "method": ({"method": "rk4"}, "method", "must be one of"),
    "quadrature": ({"quadrature": 0}, "quadrature", "integer"),
    "mode": ({"mode": "grid"}, "mode", "must be one of"),
    "order": ({"order": 3}, "order", "must be one of"),
    "rtol": ({"rtol": 1e-16}, "rtol", "1e-14"),
    "atol": ({"atol": "tight"}, "atol", "1e-14"),
    "quadrature below es's order 6": ({"method": "es", "order": 6, "quadrature": 1}, "quadrature",
                                      "needs K >= 2"),
    "out of range": ({"axes": {"links[1].mass": {"from": -1.0, "to": 1.0, "num": 3}}},
                     "links[1].mass", "run 0"),
    "out of range in a later run": ({"axes": {"springs[0].rest_length": [0.5, -0.1]}},
                                    "springs[0].rest_length", "run 1"),
    "dt out of range": ({"axes": {"simulation.dt": [0.01, 0.0]}}, "simulation.dt", "run 1"),
    "zip lengths": ({"mode": "zip", "axes": {"links[0].mass": [1.0, 2.0],
                                             "links[1].mass": [1.0]}}, "axes", "equal lengths"),
    "samples missing": ({"mode": "sample", "axes": {"links[0].mass": {"from": 1, "to": 2}}},
                        "samples", "integer"),
    "samples with a list": ({"mode": "sample", "samples": 4, "axes": {"links[0].mass": [1.0]}},
                            "links[0].mass", "range"),
    "samples in product": ({"samples": 10}, "samples", "only with mode"),
    "num missing": ({"axes": {"links[0].mass": {"from": 1.0, "to": 2.0}}}, "num", "integer"),
    "log of zero": ({"axes": {"links[0].damping": {"from": 0.0, "to": 1.0, "num": 3,
                                                   "spacing": "log"}}}, "links[0].damping",
                    "from > 0"),
    "empty list": ({"axes": {"links[0].mass": []}}, "links[0].mass", "non-empty"),
    "not a number": ({"axes": {"links[0].mass": [1.0, "heavy"]}}, "links[0].mass",
                     "finite numbers"),
    "no axes": ({"axes": {}}, "axes", "missing"),
    "t_end": ({"t_end": -1.0}, "t_end", "> 0"),
    "every": ({"every": 1.5}, "every", "integer"),
    "seed": ({"seed": -2}, "seed", "integer"),
    "scene missing": ({"scene": "nowhere.toml"}, "scene", "nowhere.toml"),
    "too many runs": ({"axes": {f"links[{i}].mass": {"from": 1.0, "to": 2.0, "num": 300}
                                for i in range(3)}}, "axes", "more than"),
}


@pytest.mark.parametrize("case", BAD_SPECS, ids=list(BAD_SPECS))
def test_bad_spec_is_one_line_exit_2_and_writes_nothing(case, tmp_path):
    changes, key, reason = BAD_SPECS[case]
    document = {"scene": SCENE, "every": 0,
                "axes": {"springs[0].stiffness": [5.0, 10.0]}}
    document.update(changes)
    path = tmp_path / "spec.toml"
    path.write_text(_toml(document))
    out = tmp_path / "out"
    result = chaingen_in_process("sweep", path, "-o", out, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert str(path) in lines[0] and key in lines[0] and reason in lines[0], lines[0]
    assert not out.exists()
    assert sorted(item.name for item in tmp_path.iterdir()) == ["spec.toml"]


def test_spec_syntax_error_and_missing_file(tmp_path):
    path = tmp_path / "spec.toml"
    path.write_text("scene = [\n")
    result = chaingen_in_process("sweep", path, "-o", tmp_path / "out", cwd=tmp_path)
    assert result.returncode == 2 and "TOML syntax error" in result.stderr
    result = chaingen_in_process("sweep", tmp_path / "none.toml", "-o", tmp_path / "out",
                                 cwd=tmp_path)
    assert result.returncode == 2 and "none.toml" in result.stderr
    assert not (tmp_path / "out").exists()


def _good_spec(tmp_path, **changes):
    document = {"scene": SCENE, "t_end": 0.1, "axes": {"springs[0].stiffness": [5.0, 10.0]}}
    document.update(changes)
    path = tmp_path / "spec.toml"
    path.write_text(_toml(document))
    return path


def test_out_holding_another_sweep_is_refused(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    record = {"digest": "0" * 64, "chunk": 1, "source": "other.toml"}
    (out / "sweep.json").write_text(json.dumps(record))
    result = chaingen_in_process("sweep", _good_spec(tmp_path), "-o", out, cwd=tmp_path)
    assert result.returncode == 2 and "another sweep spec" in result.stderr
    assert sorted(item.name for item in out.iterdir()) == ["sweep.json"]
    assert json.loads((out / "sweep.json").read_text()) == record


def test_out_that_is_no_sweep_directory_is_refused(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    result = chaingen_in_process("sweep", _good_spec(tmp_path), "-o", out, cwd=tmp_path)
    assert result.returncode == 2 and "not a sweep directory" in result.stderr
    assert (out / "notes.txt").read_text() == "mine"
    file = tmp_path / "file"
    file.write_text("x")
    result = chaingen_in_process("sweep", _good_spec(tmp_path), "-o", file, cwd=tmp_path)
    assert result.returncode == 2 and "not a directory" in result.stderr
    assert file.read_text() == "x"


@pytest.mark.parametrize("metric, reason", [("amplitude_phi9", "joints 1..3"),
                                             ("amplitude_phi1", "every > 0"),
                                             ("loudness", "not a metric")])
def test_bad_plot_metric_is_refused_before_running(tmp_path, metric, reason):
    out = tmp_path / "out"
    result = chaingen_in_process("sweep", _good_spec(tmp_path), "-o", out, "--plot", metric,
                                 cwd=tmp_path)
    assert result.returncode == 2 and reason in result.stderr, result.stderr
    assert not out.exists()


def _toml(document: dict) -> str:
    """A spec document as TOML (the subset specs use: strings, numbers, lists, inline tables)."""
    def value(item):
        if isinstance(item, str):
            return json.dumps(item)
        if isinstance(item, bool):
            return "true" if item else "false"
        if isinstance(item, float) and not math.isfinite(item):
            return "nan"
        if isinstance(item, list):
            return "[" + ", ".join(value(entry) for entry in item) + "]"
        if isinstance(item, dict):
            return "{ " + ", ".join(f"{key} = {value(entry)}" for key, entry in item.items()) \
                + " }"
        return repr(item)

    lines = [f"{key} = {value(item)}" for key, item in document.items() if key != "axes"]
    lines.append("[axes]")
    lines += [f"{json.dumps(path)} = {value(item)}"
              for path, item in document.get("axes", {}).items()]
    return "\n".join(lines) + "\n"
