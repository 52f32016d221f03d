"""`gyrostar eval starid` end to end on a one-worker LocalCluster (small)."""

import json

from gyrostar.cli.main import main


def test_cli_json_keys(capsys):
    rc = main(["eval", "-q", "starid", "--method", "extended-grid", "--preset", "qian2015", "--position-noise-px", "1",
               "--mag-noise", "0.2", "--update-period-s", "1", "--trials", "40", "--seed", "3", "--workers", "1",
               "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("success_rate", "false_id_rate", "neighbor_success_rate", "median_ms", "p99_ms"):
        assert key in out
    assert out["trials"] == 40 and out["false_id_rate"] == 0.0 and out["success_rate"] >= 0.9


def test_sweep_fig16_plot(tmp_path, capsys):
    png = tmp_path / "fig16.png"
    rc = main(["eval", "-q", "starid", "--sweep", "fig16", "--trials", "10", "--workers", "1", "--plot", str(png),
               "--json"])
    assert rc == 0 and png.stat().st_size > 1000
    fig = json.loads(capsys.readouterr().out)["figures"]["fig16"]
    sim, eq6 = fig["series"]["simulated (rms)"], fig["series"]["eq. 6"]
    # gyro-induced error grows linearly with the period; paper: ≈ 0.54 px at 10 s
    assert 0.3 < eq6[-1] < 0.8 and 0.2 < sim[-1] < 1.0 and sim[-1] > 5 * sim[0]


def test_bad_arguments_exit_2():
    assert main(["eval", "-q", "starid", "--position-noise-px", "-1", "--trials", "5"]) == 2
    assert main(["eval", "-q", "starid", "--trials", "0"]) == 2
    for bad in ("0", "1", "nan", "-1e-3"):
        assert main(["eval", "-q", "starid", "--method", "pyramid", f"--p-false-max={bad}", "--trials", "5"]) == 2


def test_p_false_max_reaches_pyramid():
    from gyrostar.hil.evaluation import eval_starid as E

    cfg = E.TrialConfig(method="pyramid", preset="qian2015", p_false_max=1e-4)
    assert E.setup(cfg)["ident"].p_false_max == 1e-4
    assert E.setup(E.TrialConfig(method="pyramid", preset="qian2015"))["ident"].p_false_max == 1e-6


def test_peer_tetra3rs_same_fields(capsys):
    """`--peer` solves the same fields with tetra3rs (database built for the field) after
    ours in the worker; both scored against the simulator's truth."""
    import pytest

    pytest.importorskip("tetra3rs", reason="tetra3rs not installed (pip install tetra3rs)")
    rc = main(["eval", "-q", "starid", "--method", "pyramid", "--fov-deg", "10", "--pixels", "1024", "--mag-limit",
               "6.5", "--position-noise-px", "0.5", "--mag-noise", "0", "--catalog-position-noise-px", "0",
               "--catalog-mag-noise", "0", "--false-stars", "2", "--trials", "30", "--seed", "5", "--workers", "1",
               "--peer", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    peer = out["peer"]
    assert peer["name"].startswith("tetra3rs") and "10.00°" in peer["name"]
    assert out["success_rate"] >= 0.95 and out["false_ids"] == 0 and peer["success_rate"] >= 0.85
    assert peer["median_ratio"] == peer["median_ms"] / out["median_ms"] and peer["wrong_rate"] <= 0.05
