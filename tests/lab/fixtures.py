"""pytest fixtures of the network lab. Load with ``pytest_plugins = ["tests.lab.fixtures"]``.

- ``lab`` (module scope): a built lab, destroyed after the module; skips with the reason when this
  machine cannot run it (not root, no namespaces, a tool missing).
- ``ros1_lab`` (module scope): the module's lab, healthy, with roscore running on the master.
- ``healthy_lab`` (function scope): the module's lab, reset to the healthy network before and
  after the test.
- ``fleet`` (module scope): a built N-site lab (tests/lab/fleet.py: a master and N-1 members, each
  behind its own modem); N is the test module's ``FLEET_SITES`` (default 3).
- ``ros2_world`` (module scope): ROS 2 (Zenoh routers, stand-in rmw_zenoh nodes) on the module's
  lab, ``fleet_ros2_world`` the same on the module's fleet; ``ros2`` (function scope): the
  module's ``ros2_world``, healthy before and after the test.
- ``lab_session`` (session scope, automatic): sweeps what a crashed earlier run left behind and
  destroys any lab of this run still up at the end.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator

import pytest

from . import cleanup
from .fleet import Fleet
from .fleet_ros2 import FleetRos2
from .lab import Lab, LabUnavailable, lab_available
from .ros2 import Ros2World


@pytest.fixture(scope="session", autouse=True)
def lab_session():
    if os.geteuid() == 0:
        cleanup.sweep_stale()
    yield
    cleanup.destroy_all()


def _built(make: Callable[[], Lab]) -> Iterator[Lab]:
    """A lab made by *make*, built, then destroyed (the test skips where it cannot be built)."""
    ok, why = lab_available()
    if not ok:
        pytest.skip(why)
    the_lab = make()
    try:
        the_lab.build()
    except LabUnavailable as exc:
        pytest.skip(str(exc))
    try:
        yield the_lab
    finally:
        the_lab.destroy()


@pytest.fixture(scope="module")
def lab(lab_session):
    yield from _built(Lab)


@pytest.fixture(scope="module")
def ros1_lab(lab):
    """The module's lab, healthy, with roscore on the master (stopped after the module)."""
    lab.reset()
    lab.start_roscore()
    yield lab
    lab.stop_roscore()


@pytest.fixture
def healthy_lab(lab):
    lab.reset()
    yield lab
    lab.reset()


@pytest.fixture(scope="module")
def fleet(lab_session, request):
    yield from _built(lambda: Fleet(getattr(request.module, "FLEET_SITES", 3)))


@pytest.fixture(scope="module")
def ros2_world(lab):
    """ROS 2 on the module's lab (tests/lab/ros2.py); a fleet module overrides it with
    ``fleet_ros2_world``."""
    with Ros2World(lab) as world:
        yield world


@pytest.fixture(scope="module")
def fleet_ros2_world(fleet):
    """ROS 2 on the module's fleet (tests/lab/fleet_ros2.py)."""
    with FleetRos2(fleet) as world:
        yield world


@pytest.fixture
def ros2(ros2_world):
    """The module's ROS 2 world, healthy before and after the test."""
    ros2_world.healthy()
    yield ros2_world
    ros2_world.healthy()
