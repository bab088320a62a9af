"""ament_python build of prsm_health (also used by ``pip install -e .``)."""

from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "prsm_health"

data_files = [
    ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
    (f"share/{PACKAGE}", ["package.xml"]),
]
for folder in ("config", "launch"):
    files = sorted(str(p) for p in Path(folder).glob("*") if p.is_file())
    if files:
        data_files.append((f"share/{PACKAGE}/{folder}", files))

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    package_data={PACKAGE: ["*.yaml", "**/*.yaml"]},
    data_files=data_files,
    zip_safe=True,
    maintainer="prsm_health maintainers",
    maintainer_email="prsm-health@example.com",
    description="Health monitoring of planetary roller screw mechanisms (PRSM) for ROS 2.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            f"prsm-health = {PACKAGE}.cli:main",
            f"prsm-health-node = {PACKAGE}.ros.node:main",
        ]
    },
)
