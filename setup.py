"""Map the repository folders onto one import tree.

driver/ -> gyrostar, mocks/ -> gyrostar.mocks, hil/ -> gyrostar.hil. Everything else
(name, dependencies, scripts) lives in pyproject.toml.
"""

from setuptools import find_packages, setup

ROOTS = {"gyrostar": "driver", "gyrostar.mocks": "mocks", "gyrostar.hil": "hil"}


def _packages():
    found = []
    for pkg, folder in ROOTS.items():
        found.append(pkg)
        found += [f"{pkg}.{sub}" for sub in find_packages(folder)]
    return found


setup(
    packages=_packages(),
    package_dir=ROOTS,
    package_data={"gyrostar": ["data/*", "protocol/*.toml", "protocol/*.json"],
                  "gyrostar.mocks": ["data/*"], "gyrostar.hil": ["scenarios/*.toml", "*.toml"]},
    include_package_data=True,
)
