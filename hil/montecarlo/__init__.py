"""Monte Carlo of the coupled loop (``gyrostar eval loop``): cases, worker, campaign, plots."""
