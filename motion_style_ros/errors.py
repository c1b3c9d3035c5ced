"""Exceptions shared by every layer of motion_style_ros."""


class MotionStyleError(Exception):
    """An error a user can fix; the CLI prints it as one line.

    Raise it with a message that says what was wrong and what is allowed, e.g.
    ``MotionStyleError("unknown style 'sad'; known styles: angry, elderly, proud")``.
    """
