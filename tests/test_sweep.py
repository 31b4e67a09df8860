"""Tests of ``skysim sweep``: configuration errors, forward-model physics against independent
references, LSM round trip with injected errors, seeding/chunking invariance, resume and
corruption recovery, memory-bounded chunks, SALib indices, dask backend (skipped without it)."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from experiments.workflows.sweep import (BLOCK_TRIALS, SweepMemoryError, SweepStateError,
                                         block_seed, chunk_trials, evaluate_trials,
                                         opponent_outputs, plan_chunks, run_chunk, run_sweep,
                                         simulate_trials, tilted_axes, trial_parameters)
from experiments.workflows.sweep_backends import SchedulerUnreachableError, run_tasks
from experiments.workflows.sweep_config import (PARAMETERS, SweepConfigError, load_config,
                                                parse_config)
from sensor.daq import Daq
from sensor.opponent import channel_outputs
from skysim.geometry import direction_vector, wrap_axial_deg
from skysim.sky import make_sky

SMALL = {"sweep": {"name": "t", "trials": 200, "seed": 3, "stops": 32},
         "parameters": {"misalignment_deg": {"uniform": [-1.0, 1.0]},
                        "noise_V": {"uniform": [1e-4, 1e-3]},
                        "sun_elevation_deg": {"uniform": [5.0, 60.0]}},
         "execution": {"chunk_trials": 64}}


def _cfg(**changes):
    raw = {k: dict(v) for k, v in SMALL.items()}
    for section, values in changes.items():
        raw.setdefault(section, {}).update(values)
    return parse_config(raw)


def _log(lines):
    return lambda msg: lines.append(msg)


# --------------------------------------------------------------------------- configuration


@pytest.mark.parametrize("raw, match", [
    ({"parameters": {"misalignment": {"uniform": [0, 1]}}}, "unknown parameter 'misalignment'"),
    ({"parameters": {"noise_V": {"uniform": [1e-3, 1e-3]}}}, "empty range"),
    ({"parameters": {"dtheta1_deg": {"uniform": [2, 1]}}}, "empty range"),
    ({"parameters": {"noise_V": {"gamma": [1, 2]}}}, "unknown distribution 'gamma'"),
    ({"parameters": {"noise_V": {"uniform": [-1e-3, 1e-3]}}}, "magnitude"),
    ({"parameters": {"sun_elevation_deg": {"uniform": [-5, 30]}}}, r"inside \(0, 90\)"),
    ({"parameters": {"dtheta1_deg": {"value": 1}, "misalignment_deg": {"value": 0}}},
     "configured twice"),
    ({"sweep": {"method": "fast99"}}, "unknown method 'fast99'"),
    ({"sweeep": {}}, r"unknown section \[sweeep\]"),
    ({"sweep": {"trails": 10}}, "unknown key 'trails'"),
    ({"sweep": {"trials": 0}}, "positive integer"),
    ({"sweep": {"pairs": ["1-4"]}}, "pairs"),
    ({"sweep": {"method": "sobol"}}, "at least one varying parameter"),
])
def test_config_rejects_bad_input_with_specific_errors(raw, match):
    with pytest.raises(SweepConfigError, match=match):
        parse_config(raw)


def test_example_configs_load(tmp_path):
    examples = sorted(Path(__file__).resolve().parents[1].joinpath("examples").glob("sweep_*.toml"))
    assert len(examples) >= 3
    methods = {load_config(p).method for p in examples}
    assert methods == {"montecarlo", "sobol", "morris"}
    bad = tmp_path / "bad.toml"
    bad.write_text("[sweep\nname=")
    with pytest.raises(SweepConfigError, match="invalid TOML"):
        load_config(bad)


def test_block_seed_is_the_spawned_child():
    children = np.random.SeedSequence(42).spawn(5)
    for b in (0, 3, 4):
        np.testing.assert_array_equal(block_seed(42, b).generate_state(4),
                                      children[b].generate_state(4))


# --------------------------------------------------------------------------- physics


def _params(n, **values):
    p = {k: np.full(n, v, dtype=float) for k, v in PARAMETERS.items()}
    p.update({k: np.broadcast_to(np.asarray(v, float), (n,)).copy() for k, v in values.items()})
    return p


def test_channel_model_reduces_to_paper_equation_without_dark_current(rng):
    """delta = 0 gives eqs. (2)-(3) exactly as sensor.opponent implements them (1e-12 V:
    the same double-precision expression, only reordered)."""
    phi = rng.uniform(-90, 90, (4, 50))
    mis = rng.uniform(-1, 1, (4, 6))
    f = rng.normal(0, 0.01, (4, 3))
    ours = opponent_outputs(phi, np.full((4, 1), 0.6), mis, f, np.zeros(4), 0.5)
    for t in range(4):
        ref = channel_outputs(phi[t], 0.6, mis[t], f[t], 0.5)
        np.testing.assert_allclose(ours[t], ref, atol=1e-12)


def test_dark_current_closed_form():
    """Ideal sensor at phi = 0: channel U2 (a = 0) reads 0.5 log10((1 + d + delta)/(1 - d +
    delta)); for d = 0.6, delta = 0.05 that is 0.5 log10(1.65 / 0.45) (closed form, 1e-12 V)."""
    u = opponent_outputs(np.zeros((1, 1)), np.full((1, 1), 0.6), np.zeros((1, 6)),
                         np.zeros((1, 3)), np.array([0.05]), 0.5)
    assert u[0, 0, 1] == pytest.approx(0.5 * np.log10(1.65 / 0.45), abs=1e-12)


def test_level_rayleigh_phi_is_heading_minus_sun_azimuth():
    """With the sun at azimuth 0 a level sensor's phi is its heading (Yang et al. 2014 and
    docs/conventions.md), for any sun elevation: exact up to 1e-9 deg."""
    n, stops = 3, 40
    p = _params(n, sun_elevation_deg=[5.0, 30.0, 70.0])
    sim = simulate_trials(p, stops, make_sky("rayleigh", dmax=1.0), Daq(None),
                          np.zeros((n, stops, 3)), np.zeros((n, stops)), 0.5)
    heading = -90 + 180 * np.arange(stops) / stops
    np.testing.assert_allclose(wrap_axial_deg(sim["phi_level"] - heading), 0,
                               atol=1e-9)
    # zenith DoP of a Rayleigh sky: sin^2 g / (1 + cos^2 g) with g = 90 - elevation
    g = np.radians(90 - p["sun_elevation_deg"])
    np.testing.assert_allclose(sim["dop_shape"], np.sin(g) ** 2 / (1 + np.cos(g) ** 2),
                               rtol=1e-12)


def test_tilted_sensor_phi_against_independent_vector_construction():
    """Tilted turntable: the Rayleigh E-vector at the boresight is perpendicular to the
    scattering plane (sun x view); projecting it on the axes rotated by scipy's Rotation
    (independent of the Rodrigues code) gives the reference phi (1e-9 deg)."""
    tilt, tilt_az, sun_el = 3.0, 40.0, 25.0
    stops = 12
    heading = -90 + 180 * np.arange(stops) / stops
    fwd, right = tilted_axes(heading, np.array([tilt]), np.array([tilt_az]))
    a = np.radians(tilt_az)
    rot = Rotation.from_rotvec(np.radians(tilt) * np.array([-np.cos(a), np.sin(a), 0.0]))
    boresight = rot.apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(boresight, direction_vector(90 - tilt, tilt_az), atol=1e-12)
    h = np.radians(heading)
    f_ref = rot.apply(np.stack([np.sin(h), np.cos(h), 0 * h], -1))
    np.testing.assert_allclose(fwd[0], f_ref, atol=1e-12)
    e = np.cross(direction_vector(sun_el, 0.0), boresight)
    r_ref = rot.apply(np.stack([np.cos(h), -np.sin(h), 0 * h], -1))
    phi_ref = wrap_axial_deg(-np.degrees(np.arctan2(r_ref @ e, f_ref @ e)) - 90)
    p = _params(1, tilt_deg=tilt, tilt_azimuth_deg=tilt_az, sun_elevation_deg=sun_el)
    sim = simulate_trials(p, stops, make_sky("rayleigh", dmax=1.0), Daq(None),
                          np.zeros((1, stops, 3)), np.zeros((1, stops)), 0.5)
    from calibration.solve import solve_pair
    phi_seen = solve_pair(sim["U"][0], (1, 2))[0]       # ideal sensor: U encodes phi exactly
    np.testing.assert_allclose(wrap_axial_deg(phi_seen - phi_ref), 0, atol=1e-9)


def test_lsm_round_trip_recovers_injected_errors_exactly():
    """Injected mounting and transmittance errors, no noise, no DAQ, level sensor: the
    Gauss-Newton LSM model is exact, so the compensated heading error must vanish (< 1e-6
    deg, the solver tolerances) while the raw error is of order of the injected degrees."""
    n, stops = 8, 64
    rng = np.random.default_rng(5)
    p = _params(n, sun_elevation_deg=rng.uniform(5, 60, n), dmax=rng.uniform(0.6, 0.8, n),
                **{f"dtheta{k}_deg": rng.uniform(-1, 1, n) for k in range(1, 7)},
                **{f"f{k}": rng.normal(0, 0.01, n) for k in range(1, 4)})
    sim = simulate_trials(p, stops, make_sky("rayleigh", dmax=1.0), Daq(None),
                          np.zeros((n, stops, 3)), np.zeros((n, stops)), 0.5)
    out = evaluate_trials(sim, ("1-2", "1-3", "2-3"))
    for tag in ("p12", "p13", "p23"):
        assert out[f"converged_{tag}"].all()
        assert np.all(out[f"compensated_3sigma_deg_{tag}"] < 1e-6)
        assert np.all(out[f"raw_3sigma_deg_{tag}"] > 0.1)
        np.testing.assert_allclose(out[f"dop_scale_{tag}"], p["dmax"], rtol=1e-8)


@pytest.mark.parametrize("sun_el", [10.0, 50.0])
def test_noise_limited_raw_error_matches_linear_propagation(sun_el):
    """Ideal level sensor, channel noise only (sigma = 0.1 mV, no DAQ): the RMS heading
    error of the pair-(1, 2) solve must match first-order propagation through eqs. (2)-(3),
    Var(phi) = sigma^2 [J^-1 J^-T]_phiphi with J = d(U1, U2)/d(phi, d) in closed form
    (dU/dphi = -(g/ln10) 4 d sin 2x / (1 - d^2 cos^2 2x), dU/dd = (g/ln10) 2 cos 2x /
    (1 - d^2 cos^2 2x), x = phi + a_i). 128 trials x 32 held-out stops: the RMS estimate has
    ~1.3 % relative standard error; 6 % tolerance (about 4.5 sigma)."""
    n, stops, sigma, g = 128, 64, 1e-4, 0.5
    rng = np.random.default_rng(11)
    p = _params(n, sun_elevation_deg=sun_el, noise_V=sigma, dmax=0.7)
    sim = simulate_trials(p, stops, make_sky("rayleigh", dmax=1.0), Daq(None),
                          rng.standard_normal((n, stops, 3)), np.zeros((n, stops)), g)
    out = evaluate_trials(sim, ("1-2",), calibrate=False, gain=g)
    rms_mc = np.sqrt(np.mean((out["raw_3sigma_deg_p12"] / 3) ** 2))
    d = 0.7 * sim["dop_shape"][0]
    phi = np.radians(sim["phi_level"][0, 1::2])
    k = g / np.log(10.0)
    J = np.empty((phi.size, 2, 2))
    for c, a in enumerate(np.radians([60.0, 0.0])):
        x = 2 * (phi + a)
        den = 1 - d ** 2 * np.cos(x) ** 2
        J[:, c, 0] = -k * 4 * d * np.sin(x) / den * np.pi / 180      # per degree
        J[:, c, 1] = k * 2 * np.cos(x) / den
    Jinv = np.linalg.inv(J)
    var_phi = sigma ** 2 * np.sum(Jinv[:, 0, :] ** 2, axis=-1)
    rms_lin = np.sqrt(np.mean(var_phi))
    assert rms_mc == pytest.approx(rms_lin, rel=0.06)


# --------------------------------------------------------------------------- execution


def test_results_identical_for_any_chunking_and_worker_count(tmp_path):
    a = run_sweep(_cfg(), tmp_path / "a", workers=2, progress=False, figures=False, log=lambda m: None)
    cfg_b = _cfg(execution={"chunk_trials": 3 * BLOCK_TRIALS})
    b = run_sweep(cfg_b, tmp_path / "b", workers=1, progress=False, figures=False,
                  log=lambda m: None)
    assert a["info"]["chunks"] == 4 and b["info"]["chunks"] == 2
    stored = pd.read_parquet(tmp_path / "a" / "trials.parquet")
    pd.testing.assert_frame_equal(stored, pd.read_parquet(tmp_path / "b" / "trials.parquet"))
    assert len(stored) == 200 and stored.trial.is_unique
    assert {"raw_3sigma_deg_p12", "compensated_3sigma_deg_p23", "noise_V"} <= set(stored)


def test_resume_skips_done_chunks_and_recomputes_corrupted_ones(tmp_path):
    out = tmp_path / "s"
    first = run_sweep(_cfg(), out, workers=1, progress=False, figures=False, log=lambda m: None)
    chunks = sorted((out / "chunks").glob("chunk-*.parquet"))
    chunks[1].unlink()                                      # lost
    data = chunks[2].read_bytes()
    chunks[2].write_bytes(data[: len(data) // 2])           # truncated partial chunk
    lines = []
    second = run_sweep(_cfg(), out, workers=1, progress=False, figures=False, log=_log(lines))
    assert second["info"]["chunks_computed"] == 2 and second["info"]["chunks_reused"] == 2
    assert any("chunk 2: unreadable" in m and "recomputing" in m for m in lines)
    pd.testing.assert_frame_equal(first["trials"], second["trials"])


def test_interrupted_sweep_keeps_finished_chunks(tmp_path):
    cfg = _cfg()
    out = tmp_path / "i"
    tasks = plan_chunks(cfg, out, cfg.digest(), cfg.trials)
    calls = []

    def stop_after_first(report):
        calls.append(report)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_tasks(run_chunk, tasks, workers=1, progress=False, on_done=stop_after_first)
    res = run_sweep(cfg, out, workers=1, progress=False, figures=False, log=lambda m: None)
    assert res["info"]["chunks_reused"] == 1 and res["info"]["chunks_computed"] == 3


def test_other_sweep_in_same_folder_is_refused(tmp_path):
    run_sweep(_cfg(), tmp_path, workers=1, progress=False, figures=False, log=lambda m: None)
    with pytest.raises(SweepStateError, match="different sweep"):
        run_sweep(_cfg(sweep={"seed": 4}), tmp_path, workers=1, progress=False,
                  figures=False, log=lambda m: None)


def test_memory_budget_bounds_chunks_and_peak_memory(tmp_path):
    """A sweep far larger than the budget is chunked (never one huge allocation) and the
    traced peak of a budget-sized chunk stays inside the budget."""
    import tracemalloc
    cfg = _cfg(sweep={"trials": 10_000_000, "stops": 182},
               execution={"chunk_trials": 10_000_000, "memory_mb": 48.0})
    size = chunk_trials(cfg)
    assert size % BLOCK_TRIALS == 0 and size * 1000 * 182 <= 48e6
    small = replace(cfg, trials=size)
    task = plan_chunks(small, tmp_path, "x", size)[0]
    tracemalloc.start()
    try:
        run_chunk(task)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 48e6
    with pytest.raises(SweepMemoryError, match="memory_mb"):
        chunk_trials(replace(cfg, memory_mb=5.0))


# --------------------------------------------------------------------------- sensitivity


def test_salib_indices_find_the_only_influential_factor(tmp_path):
    """Only the noise level acts (mounting errors fixed, tilt 0 so its azimuth is inert):
    Sobol ST of the inert factor is exactly 0 (identical model outputs), the noise level's
    S1 and ST are ~1 (within SALib's bootstrap confidence), and Morris mu* of the inert
    factor is 0."""
    base = {"sweep": {"name": "sens", "method": "sobol", "seed": 2, "stops": 32,
                      "pairs": ["1-2"]},
            "sensitivity": {"base_samples": 32, "sun_elevations_deg": [20.0, 50.0]},
            "parameters": {"noise_V": {"uniform": [1e-4, 2e-3]},
                           "tilt_azimuth_deg": {"uniform": [0.0, 360.0]}}}
    res = run_sweep(parse_config(base), tmp_path / "sobol", workers=1, progress=False,
                    log=lambda m: None)
    idx = res["indices"]
    assert set(idx.sun_elevation_deg) == {20.0, 50.0}
    inert = idx[idx.factor == "tilt_azimuth_deg"]
    np.testing.assert_allclose(inert.ST, 0.0, atol=1e-12)
    noise = idx[idx.factor == "noise_V"]
    assert np.all(np.abs(noise.ST - 1) <= np.maximum(noise.ST_conf, 0.05))
    assert all(d["factor"] == "noise_V" for d in res["info"]["dominant_factors"])
    assert (tmp_path / "sobol" / "indices.png").exists()
    base["sweep"]["method"] = "morris"
    base["sensitivity"] = {"base_samples": 6}
    res = run_sweep(parse_config(base), tmp_path / "morris", workers=1, progress=False,
                    figures=False, log=lambda m: None)
    mor = res["indices"].set_index(["output", "factor"])
    assert mor.loc[("raw_3sigma_deg_p12", "tilt_azimuth_deg"), "mu_star"] == 0.0
    assert mor.loc[("raw_3sigma_deg_p12", "noise_V"), "mu_star"] > 0.0


def test_cli_sweep_writes_tables_and_figures(tmp_path, capsys):
    from experiments.cli.main import main
    cfg = tmp_path / "c.toml"
    cfg.write_text('[sweep]\nname = "cli"\ntrials = 128\nstops = 32\nseed = 1\n'
                   '[parameters]\nnoise_V = {uniform = [0.0001, 0.001]}\n'
                   'sun_elevation_deg = {uniform = [5.0, 60.0]}\n')
    out = tmp_path / "out"
    assert main(["sweep", str(cfg), "--out", str(out), "--no-progress", "--workers", "1"]) == 0
    for name in ("trials.parquet", "summary.csv", "summary.md", "sweep.json",
                 "error_vs_sun_elevation.png", "error_vs_noise.png"):
        assert (out / name).exists(), name
    assert "128 trials" in capsys.readouterr().out
    bad = tmp_path / "bad.toml"
    bad.write_text('[parameters]\nmisalignment = {uniform = [0, 1]}\n')
    assert main(["sweep", str(bad), "--out", str(out)]) == 2


# --------------------------------------------------------------------------- dask


def test_unreachable_scheduler_is_a_clear_error():
    pytest.importorskip("dask.distributed", reason="dask.distributed not installed")
    with pytest.raises(SchedulerUnreachableError, match="no dask scheduler reachable"):
        run_tasks(run_chunk, [object()], backend="dask", scheduler="tcp://127.0.0.1:9",
                  progress=False, timeout_s=1.0)


def test_dask_local_cluster_matches_local_backend(tmp_path):
    pytest.importorskip("dask.distributed", reason="dask.distributed not installed")
    cfg = _cfg(sweep={"trials": 128})
    local = run_sweep(cfg, tmp_path / "l", workers=1, progress=False, figures=False,
                      log=lambda m: None)
    dask = run_sweep(cfg, tmp_path / "d", backend="dask", workers=2, progress=False,
                     figures=False, log=lambda m: None)
    pd.testing.assert_frame_equal(local["trials"], dask["trials"])


# --------------------------------------------------------------------------- site and date


SITE_DATE = {"sweep": {"name": "site", "method": "sobol", "seed": 4, "stops": 32,
                       "pairs": ["1-2"], "year": 2021},
             "sensitivity": {"base_samples": 16},
             "parameters": {"latitude_deg": {"uniform": [30.0, 50.0]},
                            "longitude_deg": {"uniform": [-180.0, 180.0]},
                            "day_of_year": {"uniform": [1.0, 365.0]},
                            "local_time_h": {"uniform": [9.0, 10.5]},
                            "noise_V": {"uniform": [1e-4, 1e-3]}},
             "execution": {"chunk_trials": 64}}


def test_sobol_over_site_and_date_one_sun_call_per_chunk(tmp_path, monkeypatch):
    """Each chunk computes the sun of all its trials in one array call; the elevations are
X
    lon/15 h) within 0.01 deg (the project's tolerance against SPA)."""
    import skysim.sun
    pvlib = pytest.importorskip("pvlib", reason="pvlib is the independent SPA reference")
    calls = []
    real = skysim.sun.sun_position

    def counting(times, *args, **kwargs):
        calls.append(len(times))
        return real(times, *args, **kwargs)

    monkeypatch.setattr(skysim.sun, "sun_position", counting)
    from experiments.workflows.sweep import design
    cfg = parse_config(SITE_DATE)
    n, X, cond = design(cfg)
    tasks = plan_chunks(cfg, tmp_path, cfg.digest(), n, X, cond)
    for task in tasks:
        run_chunk(task)
    assert calls == [t.stop - t.start for t in tasks] and len(tasks) == 2
    trials = pd.concat([pd.read_parquet(t.path) for t in tasks])
    utc = (pd.Timestamp("2021-01-01T00:00Z") + pd.to_timedelta(
        24 * (np.floor(trials.day_of_year) - 1) + trials.local_time_h - trials.longitude_deg / 15,
        "h"))
    ref = [pvlib.solarposition.spa_python(pd.DatetimeIndex([t]), la, lo).elevation.iloc[0]
           for t, la, lo in zip(utc, trials.latitude_deg, trials.longitude_deg)]
    np.testing.assert_allclose(trials.sun_elevation_deg, ref, atol=0.01)
    assert np.ptp(trials.sun_elevation_deg) > 15  # the design spans sites and dates


def test_site_and_date_night_is_refused_before_any_chunk(tmp_path):
    raw = {k: dict(v) for k, v in SITE_DATE.items()}
    raw["parameters"] = {**raw["parameters"], "local_time_h": {"uniform": [16.0, 23.0]}}
    with pytest.raises(SweepConfigError, match="narrow the latitude, date or local-time"):
        run_sweep(parse_config(raw), tmp_path / "night", workers=1, progress=False,
                  log=lambda m: None)
    assert not (tmp_path / "night" / "chunks").exists()


@pytest.mark.parametrize("change,match", [
    ({"parameters": {"sun_elevation_deg": {"uniform": [5.0, 60.0]}}}, "site and date"),
    ({"sensitivity": {"sun_elevations_deg": [20.0]}}, "site and date"),
    ({"sweep": {"year": 1850}}, r"year must be an integer in \[1900, 2200\]"),
    ({"parameters": {"latitude_deg": {"uniform": [-95.0, 10.0]}}}, r"inside \[-90, 90\]")])
def test_site_and_date_configuration_errors(change, match):
    raw = {k: dict(v) for k, v in SITE_DATE.items()}
    for section, values in change.items():
        raw[section] = {**raw.get(section, {}), **values}
    with pytest.raises(SweepConfigError, match=match):
        parse_config(raw)


def test_year_enters_the_digest_only_with_site_and_date():
    plain = _cfg()
    assert replace(plain, year=2000).digest() == plain.digest()
    site = parse_config(SITE_DATE)
    assert replace(site, year=2000).digest() != site.digest()
