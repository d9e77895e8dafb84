"""ament_python setup for rta_attitude (also a plain pip-installable package)."""

from glob import glob

from setuptools import find_packages, setup

package_name = "rta_attitude"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "bench", "bench.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml") + glob("config/*.json")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    package_data={package_name: ["py.typed", "ros/fastdds_profile.xml"]},
    install_requires=["setuptools", "numpy", "numba", "pyyaml"],
    # plant.simulator: basilisk (docs/basilisk.md); the version whose behaviour the tests pin
    extras_require={"basilisk": ["bsk==2.12.1"]},
    zip_safe=True,
    maintainer="rta_attitude developers",
    maintainer_email="rta-attitude@example.com",
    description="Run time assurance for spacecraft attitude (ASIF over control barrier functions)",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "rta-attitude = rta_attitude.cli.main:main",
            "plant_node = rta_attitude.ros.plant_node:main",
            "pd_controller_node = rta_attitude.ros.controller_node:main",
            "asif_filter_node = rta_attitude.ros.filter_node:main",
            "bag_recorder_node = rta_attitude.ros.recorder_node:main",
            "scene_node = rta_attitude.ros.scene_node:main",
        ],
    },
)
