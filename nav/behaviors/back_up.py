"""Back up: reverse a distance at a speed, collision-checked (Nav2 ``BackUp``). The motion is
:class:`~nav.behaviors.drive_on_heading.DriveOnHeading` run backwards, as in Nav2."""

from nav.behaviors.drive_on_heading import BackUp, BackUpOptions

__all__ = ["BackUp", "BackUpOptions"]
