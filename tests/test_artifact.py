"""Bounds rule and the OracleArtifact: derivation, round trip, validation on load."""

from __future__ import annotations

import json

import numpy as np
import pytest

from optimal_control.artifact import (
    ARTIFACT_VERSION,
    ArtifactError,
    OracleArtifact,
    build_artifact,
    write_manifest,
)
from optimal_control.bounds import BoundRule, eta0_per_phase
from optimal_control.files import OutputExistsError, check_output_folder
from optimal_control.reference import Reference, ReferenceError, static_reference
from optimal_control.wrench_qp import WrenchQP, WrenchQPConfig


def test_eta0_rule_percentile_margin_and_floor():
    phase = np.array([0] * 100 + [1] * 100)
    wrench = np.zeros((200, 6))
    wrench[:100, 1] = np.linspace(-20.0, 20.0, 100)  # phase 0 needs lateral force
    wrench[100:, 2] = 50.0  # phase 1 needs vertical force
    rule = BoundRule(percentile=100.0, margin=2.0, floor_force_n=5.0, floor_torque_nm=1.0)
    eta0 = eta0_per_phase(wrench, phase, 3, rule)
    np.testing.assert_allclose(eta0[0], [5.0, 40.0, 5.0, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(eta0[1], [5.0, 5.0, 100.0, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(eta0[2], [5.0, 5.0, 5.0, 1.0, 1.0, 1.0])  # empty phase: floor
    # Rare help: the "aided" rule covers it, a percentile over all frames misses it.
    rare = np.zeros((100, 6))
    rare[:3, 0] = 30.0
    zeros = np.zeros(100, dtype=int)
    assert eta0_per_phase(rare, zeros, 1, BoundRule())[0, 0] == pytest.approx(45.0)
    assert eta0_per_phase(rare, zeros, 1, BoundRule(frames="all"))[0, 0] == 5.0
    valid = np.ones(100, dtype=bool)
    eta0_per_phase(rare, zeros, 1, BoundRule(), valid=valid)
    assert valid.all()  # the caller's mask is left alone
    with pytest.raises(ValueError, match="Unknown bound rule"):
        eta0_per_phase(wrench, phase, 2, BoundRule(name="nope"))


def _small_artifact(g1_pin) -> OracleArtifact:
    ref = static_reference(g1_pin.q_stand, 8, 0.02, name="tiny")
    ref.phase = np.array([0, 0, 0, 1, 1, 1, 2, 2])
    ref.phase_names = ("a", "b", "c")
    ref.contacts[3:6] = False  # phase "b" airborne
    ref.extras = {"marker": np.arange(8.0)}
    ref.validate()
    profiles = {
        alpha: WrenchQP(WrenchQPConfig(alpha=alpha)).solve_reference(ref) for alpha in (1.0, 0.5)
    }
    return build_artifact(
        "tiny",
        ref,
        profiles,
        BoundRule(novice_alpha=0.5),
        extra_summary={"note": "test"},
        extra_arrays={"table": np.ones((2, 3))},
    )


def test_artifact_round_trip(tmp_path, g1_pin):
    art = _small_artifact(g1_pin)
    weight = g1_pin.total_mass_kg * 9.81
    # Phase "b" (no contact) needs the weight; the others need only the floor.
    assert art.eta0[1, 2] >= weight
    assert art.eta0[0, 2] == BoundRule().floor_force_n
    folder = art.save(tmp_path / "art")
    assert (folder / "plots" / "eta0.png").is_file()
    assert (folder / "plots" / "wrench_0.50.png").is_file()
    loaded = OracleArtifact.load(folder)
    assert loaded.phase_names == ("a", "b", "c")
    np.testing.assert_allclose(loaded.eta0, art.eta0)
    np.testing.assert_allclose(loaded.profiles[0.5].wrench_w, art.profiles[0.5].wrench_w)
    np.testing.assert_allclose(loaded.reference.q, art.reference.q)
    np.testing.assert_allclose(loaded.reference.extras["marker"], np.arange(8.0))
    np.testing.assert_allclose(loaded.extra_arrays["table"], np.ones((2, 3)))
    assert loaded.extra_summary == {"note": "test"}
    light = OracleArtifact.read_summary(folder)  # oracle.json alone, no arrays
    assert (light.task, light.phase_names) == ("tiny", ("a", "b", "c"))
    np.testing.assert_array_equal(light.eta0, loaded.eta0)
    assert "heading frame" in light.eta0_frame
    summary = light.raw
    assert summary["eta0_per_phase"]["b"]["force_n"][2] == pytest.approx(art.eta0[1, 2])
    assert summary["alphas"] == [1.0, 0.5]
    assert summary["rule"]["name"] == "percentile_margin"


def test_artifact_load_rejects_bad_folders(tmp_path, g1_pin):
    with pytest.raises(ArtifactError, match=r"oracle\.json is missing"):
        OracleArtifact.load(tmp_path)
    folder = _small_artifact(g1_pin).save(tmp_path / "art", plots=False)
    summary = json.loads((folder / "oracle.json").read_text())
    summary["version"] = 999
    (folder / "oracle.json").write_text(json.dumps(summary))
    with pytest.raises(ArtifactError, match="version 999"):
        OracleArtifact.load(folder)
    with pytest.raises(ArtifactError, match="version 999"):
        OracleArtifact.read_summary(folder)
    summary["version"] = ARTIFACT_VERSION
    summary["eta0"] = [[1.0] * 6]  # one row for three phases
    (folder / "oracle.json").write_text(json.dumps(summary))
    with pytest.raises(ArtifactError, match=r"oracle\.json' differs from manifest\.json"):
        OracleArtifact.load(folder)  # an edit the manifest does not know: refused
    write_manifest(folder)  # seal the deliberate edit: the content check now speaks
    with pytest.raises(ArtifactError, match="eta0 has shape"):
        OracleArtifact.load(folder)
    with pytest.raises(
        ArtifactError, match=r"oracle\.json: eta0 has shape \(1, 6\), expected \(3, 6\)"
    ):
        OracleArtifact.read_summary(folder)


def test_partial_or_mixed_artifacts_do_not_load(tmp_path, g1_pin):
    """The manifest names the file that is missing, truncated or from another artifact."""
    art = _small_artifact(g1_pin)
    first = art.save(tmp_path / "a", plots=False)
    manifest = json.loads((first / "manifest.json").read_text())
    assert set(manifest["files"]) == {"arrays.npz", "oracle.json"}
    assert set(manifest["code_revision"]) == {"commit", "dirty"}
    assert manifest["files"]["arrays.npz"]["size_bytes"] == (first / "arrays.npz").stat().st_size
    art.eta0 = art.eta0 * 2.0
    second = art.save(tmp_path / "b", plots=False)
    OracleArtifact.load(second)

    (first / "manifest.json").rename(tmp_path / "manifest.json")
    with pytest.raises(ArtifactError, match="manifest.json is missing"):
        OracleArtifact.load(first)  # killed before the manifest (old non-atomic writer)
    (tmp_path / "manifest.json").rename(first / "manifest.json")
    (first / "oracle.json").write_bytes((second / "oracle.json").read_bytes())
    with pytest.raises(ArtifactError, match=r"oracle\.json' differs"):
        OracleArtifact.load(first)  # the walk's eta0 with the dance's arrays
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    for name in ("oracle.json", "manifest.json"):
        (mixed / name).write_bytes((second / name).read_bytes())
    data = (second / "arrays.npz").read_bytes()
    (mixed / "arrays.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ArtifactError, match=r"arrays\.npz' differs"):
        OracleArtifact.load(mixed)  # truncated arrays
    write_manifest(mixed)
    with pytest.raises(ArtifactError, match=r"arrays\.npz' is not an \.npz archive"):
        OracleArtifact.load(mixed)  # truncated and sealed: the npz reader names the file


def test_saving_over_an_artifact_needs_overwrite_and_leaves_no_stale_files(tmp_path, g1_pin):
    art = _small_artifact(g1_pin)
    folder = tmp_path / "art"
    art.save(folder, plots=False)
    (folder / "solution.npz").write_bytes(b"stale file of another task")
    with pytest.raises(OutputExistsError, match="--overwrite"):
        art.save(folder, plots=False)
    with pytest.raises(OutputExistsError, match="--overwrite"):
        check_output_folder(folder, overwrite=False)
    art.save(folder, plots=False, overwrite=True)
    assert sorted(p.name for p in folder.iterdir()) == [
        "arrays.npz",
        "manifest.json",
        "oracle.json",
    ]
    assert [p.name for p in tmp_path.iterdir()] == ["art"]  # no temporary folder left
    OracleArtifact.load(folder)


def test_reference_validation_names_the_problem(g1_pin):
    ref = static_reference(g1_pin.q_stand, 4, 0.02)
    bad_quat = Reference(**{**ref.__dict__, "q": ref.q.copy()})
    bad_quat.q[2, 3:7] *= 2.0
    with pytest.raises(ReferenceError, match="quaternion of frame 2"):
        bad_quat.validate()
    bad_nan = Reference(**{**ref.__dict__, "v": ref.v.copy()})
    bad_nan.v[3, 0] = np.nan
    with pytest.raises(ReferenceError, match="'v' has NaN"):
        bad_nan.validate()
    with pytest.raises(ReferenceError, match="shape"):
        Reference(**{**ref.__dict__, "a": ref.a[:, :30]}).validate()


def test_eta0_bounds_the_reference_heading_axes():
    """The env bounds the assist wrench per heading axis: a reference that faces another way or
    turns needs the same eta0 as one facing +x (fx and fy do not swap)."""
    from optimal_control.bounds import wrench_in_heading_frame

    rng = np.random.default_rng(0)
    wrench_h = rng.normal(size=(300, 6)) * np.array([10.0, 40.0, 5.0, 50.0, 20.0, 10.0])
    phase = np.zeros(300, dtype=int)
    expected = eta0_per_phase(wrench_h, phase, 1)
    for yaw in (np.full(300, np.pi / 2), np.linspace(0.0, 2 * np.pi, 300)):
        quat_xyzw = np.stack([0 * yaw, 0 * yaw, np.sin(yaw / 2), np.cos(yaw / 2)], axis=1)
        c, s = np.cos(yaw), np.sin(yaw)
        wrench_w = wrench_h.copy()
        for k in (0, 3):  # the world wrench of a robot heading along yaw
            wrench_w[:, k] = c * wrench_h[:, k] - s * wrench_h[:, k + 1]
            wrench_w[:, k + 1] = s * wrench_h[:, k] + c * wrench_h[:, k + 1]
        back = wrench_in_heading_frame(wrench_w, quat_xyzw)
        np.testing.assert_allclose(back, wrench_h, atol=1e-9)
        np.testing.assert_allclose(eta0_per_phase(back, phase, 1), expected, rtol=1e-9)
        assert not np.allclose(eta0_per_phase(wrench_w, phase, 1), expected, rtol=0.05)
