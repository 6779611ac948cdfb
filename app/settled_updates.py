"""Number widgets that act once the person stops typing.

A slider's number box sends a value per keystroke: typing "800" sends 8, 80,
800.  Applying each of them (a new BA column window, new textures) costs time,
and a write-back of an older value while the person types further rewrites
the box under their fingers.  :func:`settled` passes an update on only once
the widget has kept its value for :data:`SETTLE_S` seconds, so only the value
typed (or the slider position released) is applied.
"""

from __future__ import annotations

import asyncio
from typing import Any, Awaitable, Callable

#: Quiet time (seconds) after the last change of a widget before it is applied; longer than the gap between
#: two keystrokes of a person typing a number.
SETTLE_S = 0.4


def settled(callback: Callable[[Any], Awaitable[None]], delay: float = SETTLE_S) -> Callable[[Any], Awaitable[None]]:
    """A viser ``on_update`` callback that hands an event to ``callback`` once its widget has settled.

    Parameters
    ----------
    callback : async callable
        Gets the event of the last change (e.g. :meth:`app.action_queue.ActionQueue.guard`'s wrapper,
        which then reads the widget's value: the settled one).
    delay : float
        Seconds without a further change of the same widget.

    Returns
    -------
    async callable
        Runs on viser's event loop (each update is its own task there, so waiting does not hold up others).
    """
    latest: dict[int, object] = {}  # widget -> token of its newest update

    async def on_update(event: Any) -> None:
        if getattr(event, "client", None) is None:  # the app's own write: passed on at once, a typed value stays due
            await callback(event)
            return
        key = id(event.target)
        token = latest[key] = object()
        await asyncio.sleep(delay)
        if latest.get(key) is token:  # no newer update of this widget arrived meanwhile
            del latest[key]
            await callback(event)

    return on_update
