"""``gyrostar eval starcount``: stars in a random square field (paper 001, Table 1)."""

from __future__ import annotations

from gyrostar.cli.main import add_json

HELP = "distribution of the number of catalog stars in a random square field (paper 001 Table 1)"

# Paper 001 (Qian et al. 2015), Table 1: 10,000 random boresights, 4x4 deg, Tycho-2 V <= 7.5 (%)
PAPER001_TABLE1 = {"0": 0.04, "1": 0.56, "2": 1.40, "3": 4.17, "4": 5.95, "5": 8.17, "6": 9.75, ">6": 69.96}


def configure(parser) -> None:
    parser.add_argument("--fov-deg", type=float, default=4.0, help="full square field of view (deg)")
    parser.add_argument("--mag-limit", type=float, default=7.5, help="limiting V magnitude")
    parser.add_argument("--trials", type=int, default=10000, help="number of random attitudes")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.add_argument("--catalog", default="hip2", help="catalog name: hip2 or gaia")
    parser.add_argument("--epoch", type=float, default=2025.0, help="catalog epoch (Julian year)")
    parser.add_argument("--band", choices=("V", "VT"), default="V",
                        help="magnitude the limit applies to: Johnson V, or Tycho V_T estimated from V and B-V "
                             "(paper 001 cut Tycho-2)")
    add_json(parser)


def run(args) -> int:
    from gyrostar.catalog import load_catalog
    from gyrostar.cli.output import emit, progress

    from .field_count import BINS, star_count_distribution

    if args.band == "V":
        cat = load_catalog(args.catalog, args.mag_limit, args.epoch)
        vectors = cat.vectors
    else:  # V_T >= V - 0.03 for any B - V >= -0.25 in the catalog: load a little deeper, then cut
        cat = load_catalog(args.catalog, args.mag_limit + 0.05, args.epoch)
        vectors = cat.vectors[cat.tycho_vt() <= args.mag_limit]
    with progress(args, "random fields", args.trials) as advance:
        res = star_count_distribution(vectors, args.fov_deg, args.trials, args.seed, advance=advance)
    dist = res["distribution"]
    result = dict(dist)
    result.update({"trials": args.trials, "fov_deg": args.fov_deg, "mag_limit": args.mag_limit,
                   "catalog": args.catalog, "band": args.band, "catalog_stars": len(vectors), "seed": args.seed})
    lines = [f"{len(vectors)} {args.catalog} stars with {args.band} <= {args.mag_limit}, {args.fov_deg} deg square "
             f"field, {args.trials} random attitudes (seed {args.seed})", "stars   this run %   paper 001 Table 1 %"]
    compare = args.fov_deg == 4.0 and args.mag_limit == 7.5
    if compare:
        result["paper001_table1"] = PAPER001_TABLE1
    for b in BINS:
        paper = f"{PAPER001_TABLE1[b]:8.2f}" if compare else ""
        lines.append(f"{b:>5}   {dist[b]:10.2f}   {paper}")
    lines.append(f" mean   {dist['mean']:10.2f}")
    emit(args, result, "\n".join(lines))
    return 0
