"""A performer's health in the terms ``diagnostic_updater`` users know: OK, WARN or ERROR, with the
rules' reasons (no ROS here: the stylizer node turns it into a DiagnosticStatus once a second).

Over the time since the last status:

- ERROR: frames came in but none went out (every one dropped), or the model's output had to be
  thrown away (a non-finite pose restarted the stream).
- WARN: no input; frames dropped; the stream restarted on a new timeline; the input rate below
  ``RATE_SHARE`` of the nominal rate; the processing latency's p99 over ``max_latency_ms``.
- OK otherwise.
"""

from __future__ import annotations

OK, WARN, ERROR = 0, 1, 2
RATE_SHARE = 0.8


def health(before: dict[str, int], now: dict[str, int], seconds: float, nominal_fps: float,
           latency_p99_ms: float, max_latency_ms: float) -> tuple[int, list[str]]:
    """The level and its reasons from two snapshots of a performer's counters ``seconds`` apart
    (``frames_in``, ``frames_out``, ``dropped``, ``restarted_<reason>``)."""
    d = {k: now[k] - before.get(k, 0) for k in now}
    errors, warnings = [], []
    if d["frames_in"] and not d["frames_out"]:
        errors.append(f"{d['frames_in']} frames in, none out")
    if d.get("restarted_non_finite_output"):
        errors.append("the model's output was not finite")
    if not d["frames_in"]:
        warnings.append("no input")
    elif seconds > 0 and d["frames_in"] / seconds < RATE_SHARE * nominal_fps:
        warnings.append(f"input at {d['frames_in'] / seconds:.1f} Hz, nominal {nominal_fps:g} Hz")
    if d["dropped"]:
        warnings.append(f"{d['dropped']} dropped")
    if d.get("restarted_new_timeline"):
        warnings.append("restarted on a new clock or place")
    if latency_p99_ms > max_latency_ms:
        warnings.append(f"latency p99 {latency_p99_ms:.1f} ms over {max_latency_ms:g} ms")
    if errors:
        return ERROR, errors + warnings
    return (WARN, warnings) if warnings else (OK, [])
