"""Star-identification safety (small version of ``python -m gyrostar.reliability.starid_safety``):
false stars and magnitude noise through the tracker never give a wrong attitude."""

from gyrostar.reliability.starid_safety import WRONG_BORESIGHT_PX, run


def test_false_stars_never_give_a_wrong_attitude():
    r = run(trials=300, seed=11)
    assert r["wrong_attitudes"] == 0 and r["outputs_with_wrong_ids"] == 0
    assert r["output_fraction"] > 0.4                       # the identifiers did answer
    assert r["by_false_stars"][5]["outputs"] > 0           # including with 5 false stars
    assert r["boresight_err_arcsec_max"] < r["wrong_boresight_threshold_arcsec"] / WRONG_BORESIGHT_PX * 3
    assert r["tracker_counts"]["tracked"] > 0 and r["tracker_counts"]["acquired"] > 0
