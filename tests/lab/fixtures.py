"""pytest fixtures of the network lab. Load with ``pytest_plugins = ["tests.lab.fixtures"]``.

- ``lab`` (module scope): a built lab, destroyed after the module; skips with the reason when this
  machine cannot run it (not root, no namespaces, a tool missing).
- ``healthy_lab`` (function scope): the module's lab, reset to the healthy network before and
  after the test.
- ``fleet`` (module scope): a built N-site lab (tests/lab/fleet.py: a master and N-1 members, each
  behind its own modem); N is the test module's ``FLEET_SITES`` (default 3).
- ``lab_session`` (session scope, automatic): sweeps what a crashed earlier run left behind and
  destroys any lab of this run still up at the end.
"""

from __future__ import annotations

import os

import pytest

from . import cleanup
from .fleet import Fleet
from .lab import Lab, LabUnavailable, lab_available


@pytest.fixture(scope="session", autouse=True)
def lab_session():
    if os.geteuid() == 0:
        cleanup.sweep_stale()
    yield
    cleanup.destroy_all()


@pytest.fixture(scope="module")
def lab(lab_session):
    ok, why = lab_available()
    if not ok:
        pytest.skip(why)
    the_lab = Lab()
    try:
        the_lab.build()
    except LabUnavailable as exc:
        pytest.skip(str(exc))
    try:
        yield the_lab
    finally:
        the_lab.destroy()


@pytest.fixture
def healthy_lab(lab):
    lab.reset()
    yield lab
    lab.reset()


@pytest.fixture(scope="module")
def fleet(lab_session, request):
    ok, why = lab_available()
    if not ok:
        pytest.skip(why)
    the_fleet = Fleet(getattr(request.module, "FLEET_SITES", 3))
    try:
        the_fleet.build()
    except LabUnavailable as exc:
        pytest.skip(str(exc))
    try:
        yield the_fleet
    finally:
        the_fleet.destroy()
