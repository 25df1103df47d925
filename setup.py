"""Packaging beyond pyproject.toml: the default robot (configs/wolfgang, the one source) is shipped inside the
package as wolfcal/data/robots/wolfgang, so every command finds it after a plain `pip install .`."""

from setuptools import find_packages, setup

ROBOT_PACKAGE = "wolfcal.data.robots.wolfgang"

setup(
    packages=find_packages(include=["wolfcal", "wolfcal.*"]) + [ROBOT_PACKAGE],
    package_dir={ROBOT_PACKAGE: "configs/wolfgang"},
    package_data={ROBOT_PACKAGE: ["*.yaml", "*.urdf"]},
)
