"""The desk for a real motor (docs/real-motor.md): find the motors on a line, back them
up to a file, restore them, compare.

* :mod:`.linescan` - ``coolmuscle scan``: IDs, K20 rate, firmware (queries only);
* :mod:`.image` - a motor as a backup holds it (:class:`MotorImage`, :class:`ChainImage`);
* :mod:`.reading` - reading a motor: sans-IO operations for any client driver;
* :mod:`.backupfile` - the backup file, a ``coolmuscle run`` script, written and checked;
* :mod:`.restorer` - the parts of a restore, in order, each read back;
* :mod:`.diff` - ``coolmuscle params diff``;
* :mod:`.connection` - the blocking entry points (:class:`DeskLine`, :func:`backup`,
  :func:`restore`, :func:`factory_image`);
* :mod:`.commands` - the typer commands.

The meaning of each K parameter is :mod:`coolmuscle.motor.state.catalogue`.
"""

from __future__ import annotations

from .backupfile import load_backup, parse_backup, render_backup
from .connection import DeskLine, backup, factory_image, restore
from .diff import Difference, diff_images, format_diff
from .errors import BackupFileError, DeskError, FirmwareMismatchError, NoMotorError
from .image import ChainImage, MotorImage
from .linescan import FoundMotor, ScanResult, scan, scan_bound
from .restorer import Outcome, Part, RestoreReport, plan_restore, run_restore

__all__ = ["scan", "scan_bound", "ScanResult", "FoundMotor", "DeskLine", "backup", "restore",
           "factory_image", "ChainImage", "MotorImage", "render_backup", "parse_backup",
           "load_backup", "diff_images", "format_diff", "Difference", "plan_restore",
           "run_restore", "Part", "Outcome", "RestoreReport", "DeskError", "NoMotorError",
           "BackupFileError", "FirmwareMismatchError"]
