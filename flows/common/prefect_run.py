"""Prefect when a Prefect API is configured; the same functions, run directly, when not.

Without ``PREFECT_API_URL`` every Prefect flow run (and every task called outside one) starts a
temporary local API server first: ~15–20 s of a command that itself may take a second, and the
run history it records is thrown away when the command ends. So a command runs its flow as a
Prefect flow run only when an API is configured (:func:`api_url`); otherwise it calls the flow's
function, ``Flow.fn`` in Prefect's terms, and the tasks it calls run as plain calls. Either
way the work is the same code: the flow's function and the task functions it calls.

:func:`flow` and :func:`task` are Prefect's decorators, applied on first use: importing a
flow module does not import Prefect (~2.5 s on a warm machine), so commands that run without
an API never load it. What they return:

* :class:`LazyFlow` — calling it is a Prefect flow run (as calling a ``@flow`` function is);
  ``.fn`` is the function; :func:`run_flow` picks one of the two; everything else
  (``with_options``, ``name``, …) is the Prefect flow's.
* :class:`LazyTask` — inside a Prefect flow run it is the Prefect task (a task run, with its
  retries, on the flow's task runner: ``submit``); outside one, calling it calls the function,
  retried as the task's ``retries`` and ``retry_delay_seconds`` say (:func:`call_with_retries`).
  Tasks never cache their results (``cache_policy=NO_CACHE``).

Served deployments (``valvemon serve``) load their flow by its entry point and need Prefect's
own flow object: :mod:`flows.orchestration.nightly` uses Prefect's decorator directly.
"""

from __future__ import annotations

import functools
import logging
import os
import sys
import time
import tomllib
from pathlib import Path
from typing import Any, Callable, Sequence

API_URL_SETTING = "PREFECT_API_URL"


def _profile_api_url() -> str | None:
    """``PREFECT_API_URL`` of the active profile in Prefect's profiles file (``prefect config set``)."""
    home = Path(os.environ.get("PREFECT_HOME") or Path.home() / ".prefect").expanduser()
    path = Path(os.environ.get("PREFECT_PROFILES_PATH") or home / "profiles.toml").expanduser()
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError):
        return None
    active = os.environ.get("PREFECT_PROFILE") or data.get("active") or "ephemeral"
    value = data.get("profiles", {}).get(active, {}).get(API_URL_SETTING)
    return str(value) if value else None


def api_url() -> str | None:
    """The configured Prefect API, or None: ``$PREFECT_API_URL``, else the active Prefect profile.

    Answered without importing Prefect. When Prefect is already loaded (a test server, a
    temporary API started for Dask workers) its own settings answer, which also see
    ``temporary_settings``.
    """
    if "prefect.settings" in sys.modules:
        from prefect.settings import PREFECT_API_URL

        return PREFECT_API_URL.value() or None
    if API_URL_SETTING in os.environ:
        return os.environ[API_URL_SETTING] or None
    return _profile_api_url()


def in_flow_run() -> bool:
    """Whether this thread runs inside a Prefect flow run (never, if Prefect was not loaded)."""
    if "prefect.context" not in sys.modules:
        return False
    from prefect.context import FlowRunContext

    return FlowRunContext.get() is not None


def quiet_prefect_console() -> None:
    """Keep Prefect's console log (run states, tracebacks) off the command line's stderr.

    The command prints its own summary and a one-line error; the flow and task runs are still
    recorded by the Prefect API. Applies to logging set up later (environment) and now.
    """
    os.environ["PREFECT_LOGGING_HANDLERS_CONSOLE_LEVEL"] = "CRITICAL"
    for lg in [logging.getLogger(), *(v for v in logging.root.manager.loggerDict.values() if isinstance(v, logging.Logger))]:
        for h in lg.handlers:
            if type(h).__name__ == "PrefectConsoleHandler":
                h.setLevel(logging.CRITICAL)


def call_with_retries(fn: Callable, args: tuple, kwargs: dict, retries: int, delays: float | Sequence[float] | None) -> Any:
    """``fn(*args, **kwargs)``, called again up to ``retries`` times after an exception, waiting as
    Prefect would: retry ``i`` (from 0) waits ``delays[min(i, len(delays) - 1)]`` seconds."""
    for attempt in range(retries + 1):
        try:
            return fn(*args, **kwargs)
        except Exception:
            if attempt == retries:
                raise
            if isinstance(delays, Sequence):
                wait = delays[min(attempt, len(delays) - 1)] if delays else 0.0
            else:
                wait = delays or 0.0
            time.sleep(wait)
    raise AssertionError("unreachable")


class _Lazy:
    """A function and the options of a Prefect decorator applied to it on first use."""

    _decorator = ""

    def __init__(self, fn: Callable, options: dict[str, Any]):
        self.fn = fn
        self.options = options
        functools.update_wrapper(self, fn)

    @functools.cached_property
    def prefect(self):
        """The Prefect object (imports Prefect)."""
        import prefect

        options = dict(self.options)
        if self._decorator == "task":
            from prefect.cache_policies import NO_CACHE

            options.setdefault("cache_policy", NO_CACHE)
        return getattr(prefect, self._decorator)(**options)(self.fn)

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.prefect, name)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.options.get('name') or self.fn.__name__}>"


class LazyFlow(_Lazy):
    """A Prefect flow made on first use; calling it is a Prefect flow run (module doc)."""

    _decorator = "flow"

    def __call__(self, *args, **kwargs):
        return self.prefect(*args, **kwargs)


class LazyTask(_Lazy):
    """A Prefect task inside a flow run; outside one, the function with the task's retries (module doc)."""

    _decorator = "task"

    def __call__(self, *args, **kwargs):
        if in_flow_run():
            return self.prefect(*args, **kwargs)
        return call_with_retries(self.fn, args, kwargs, self.options.get("retries") or 0, self.options.get("retry_delay_seconds"))

    def with_options(self, **options) -> LazyTask:
        """The same task with other options (``retries``, ``retry_delay_seconds``, …)."""
        return LazyTask(self.fn, {**self.options, **options})


def flow(**options) -> Callable[[Callable], LazyFlow]:
    """``prefect.flow(**options)``, applied on first use."""
    return lambda fn: LazyFlow(fn, options)


def task(**options) -> Callable[[Callable], LazyTask]:
    """``prefect.task(**options)`` (default ``cache_policy=NO_CACHE``), applied on first use."""
    return lambda fn: LazyTask(fn, options)


def run_flow(flow_: LazyFlow, /, prefect_options: Callable[[], dict] | None = None, **parameters) -> Any:
    """Run a command's flow: a Prefect flow run if an API is configured (its console log kept
    off stderr; ``prefect_options()``, if given, are its ``with_options``, e.g. a task runner),
    else its function directly, with no Prefect at all."""
    if api_url():
        quiet_prefect_console()
        return (flow_.with_options(**prefect_options()) if prefect_options else flow_)(**parameters)
    return flow_.fn(**parameters)
