"""The flight/ground import contract (make lint, import-linter) covers every flight module:
a new module under driver/ cannot escape it by not being listed."""

import tomllib


def test_contract_lists_every_flight_module(repo):
    cfg = tomllib.loads((repo / "pyproject.toml").read_text())["tool"]["importlinter"]
    (contract,) = [c for c in cfg["contracts"] if c["type"] == "forbidden"]
    assert set(contract["forbidden_modules"]) == {"gyrostar.mocks", "gyrostar.hil"}
    listed = set(contract["source_modules"])
    flight = {p.stem if p.suffix == ".py" else p.name for p in (repo / "driver").iterdir()
              if (p.suffix == ".py" and p.stem != "__init__") or (p.is_dir() and (p / "__init__.py").exists())}
    assert {f"gyrostar.{m}" for m in flight} == listed
