"""Attack on time: one fingertip stamped 1e12 s among good ones, into the planner node (loaded by its node
type, as the launcher does) through the in-process harness. The planner must refuse it alone and serve the
good ones after it."""

from __future__ import annotations

import asyncio
import time

import numpy as np

from flexsheet.runtime.plugins import node_class
from flexsheet.runtime.testing import NodeHarness
from messages import Fingertip, Header
from messages import topics as T

__all__ = ["future_stamp"]


def _tip(stamp: float, y: float) -> Fingertip:
    p = np.array([0.02, y, 0.0])
    return Fingertip(header=Header(stamp=stamp), position=p, covariance=np.eye(3) * 1e-8, valid=True,
                     predicted_position=p, prediction_horizon=0.0, exposure_stamp=stamp - 0.012)


def future_stamp(n_after: int = 10) -> dict:
    """3 good fingertips, one stamped 1e12, ``n_after`` good ones: counts of refusals and of served
    targets."""
    planner = node_class("planner")

    async def scenario() -> dict:
        params = {"object_stiffness": 20.0, "stiffness_from_scene": False}
        async with NodeHarness(planner, params=params) as h:
            for k in range(3):
                h.inject(T.FINGERTIP, _tip(time.time(), 0.001 * k))
                await h.wait_for(T.SHEET_TARGET, n=k + 1)
            h.inject(T.FINGERTIP, _tip(1e12, 0.0))
            await h.wait_for(T.SHEET_TARGET, n=4)
            for k in range(n_after):
                h.inject(T.FINGERTIP, _tip(time.time(), 0.003 + 0.001 * k))
                await h.wait_for(T.SHEET_TARGET, n=5 + k)
            st = [m.status for m in h.messages(T.SHEET_TARGET)]
            return {"future_status": st[3], "rejected": h.rejected(T.FINGERTIP),
                    "served_after": sum(not s.startswith("hold") for s in st[4:]), "sent_after": n_after}

    return asyncio.run(scenario())
