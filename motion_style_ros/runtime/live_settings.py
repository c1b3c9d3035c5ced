"""The stylizer node's live parameters without ROS: their values, the check of a change, its way to
the sessions, and the reference clips staged on the way (the node only forwards rclpy's callbacks).

The ROS 2 rules: a change is checked in the on-set callback (:meth:`LiveSettings.check`: a reason
fails ``ros2 param set`` with it), accepted after it (:meth:`LiveSettings.accept`: queued, or a new
reference clip sent to a worker first), and applied by the streams' thread before its next frame
(:meth:`LiveSettings.apply_pending`). A clip the worker cannot use queues a revert of the
parameter to the clip in use, which the node sets again through ROS (so ``ros2 param get`` shows
it); that set is not checked again.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.runtime import stylizer_settings as settings_
from motion_style_ros.runtime.backends import Backend
from motion_style_ros.runtime.references import REVERT, References

# what may change how a reference clip's codes are used (its codes stay; the clip is not read again)
_USES_REFERENCE = {"reference", "target_style", "latent_seed", "seed_spread"}


class LiveSettings:
    """The live parameters (:data:`~motion_style_ros.runtime.stylizer_settings.DYNAMIC`) of the
    sessions ``sessions`` (one per performer, one model) of backend ``spec``, started from
    ``values``, each checked once here; ``log_error``: where a worker's failure is said."""

    def __init__(self, sessions: list, spec: Backend, values: dict,
                 log_error: Callable[[str], None]) -> None:
        self.sessions, self.spec = sessions, spec
        self.styles = sessions[0].styles
        self.values = {k: values[k] for k in settings_.DYNAMIC}
        for key, value in self.values.items():
            if reason := settings_.problem(key, value, self.styles, spec):
                raise MotionStyleError(f"parameter {key}: {reason}")
        self.pending: deque[dict] = deque()  # accepted changes, for the streams' thread, in order
        self.references = References(sessions[0], self.pending, log_error,
                                     "the latent seed" if spec.latent_seeds else "the styles' own inputs")
        self._reference = None  # the codes of the reference parameter's clip, once read
        self._reverting: str | None = None  # a revert being set: taken without a check
        if self.values["reference"]:
            self.references.staged[self.values["reference"]] = self.references.read(self.values["reference"])
        self._apply(self.values)

    def check(self, changes: dict) -> str | None:
        """Why ``changes`` cannot be taken (one line), or None; nothing changes yet."""
        for key, value in changes.items():
            if reason := settings_.problem(key, value, self.styles, self.spec):
                return reason
        path = changes.get("reference")
        if path and path != self._reverting:
            try:
                self.references.check(path)
            except MotionStyleError as exc:
                return " ".join(str(exc).split())
        return None

    def accept(self, changes: dict) -> None:
        """Queue a checked change for the streams' thread; a new reference clip first goes to a
        worker thread, which queues it once it is read."""
        if not changes:
            return
        path = changes.get("reference")
        reverting, self._reverting = "reference" in changes and path == self._reverting, None
        if reverting and path:
            self.references.staged[path] = self._reference
        elif path:
            self.references.load(path, self.values["reference"], changes)
            return
        self.pending.append(changes)

    def apply_pending(self, revert: Callable[[str], None]) -> None:
        """Apply the queued changes in order; ``revert(path)`` sets the reference parameter back
        through ROS (its on-set and post-set callbacks run inline and come back here)."""
        while self.pending:
            changes = self.pending.popleft()
            if REVERT in changes:
                self._reverting = changes[REVERT]
                revert(self._reverting)
                continue
            self._apply(changes)
            self.values.update(changes)

    def _apply(self, changes: dict) -> None:
        """Hand changed controls to every session (:func:`~.stylizer_settings.apply`). A reference
        clip was read (and checked) when it was set; it stays in use when the target style or the
        seed changes, without being read again."""
        values = {**self.values, **changes}
        reference = None
        if self.spec.reference_clips and values["reference"] and _USES_REFERENCE & changes.keys():
            reference = (self.references.staged.pop(values["reference"]) if "reference" in changes
                         else self._reference)
        if "reference" in changes or reference is not None:
            self._reference = reference  # None once the parameter is emptied
        settings_.apply(self.sessions, self.spec, self.values, changes, reference)
