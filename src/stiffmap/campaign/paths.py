"""Files named in ``campaign.toml`` stay inside the campaign directory (unless the user allows otherwise).

``campaign.toml`` names the camera file (``camera.file``) or rig file
(``cameras.rig``), the images (the ``[images]`` patterns), the recordings
(``sensor.recordings[i].file``) and the robot's file (``robot.urdf``,
``robot.legs``: :func:`stiffmap.campaign.robot.robot_file`), relative to the
campaign directory. The files stiffmap keeps there under fixed names (``stiffmap.db``,
``truth.json``) follow the same rule (:func:`own_file`): a symbolic link that leads out
would make a run write, or a report read, another folder's file. A name that leads outside it, by an
absolute path, by ``..`` or through a symbolic link, is refused with the key
(and the position, load and repeat of an image), the name and the option that
allows it, ``--allow-outside-paths`` (``stiffmap run`` and ``stiffmap report``):
a campaign directory then says all it reads, and a spec copied from elsewhere
cannot make ``stiffmap`` read (and hash, and put in its database and report)
files the user did not mean to give. The test itself is
:func:`stiffmap.io.leaves_directory`, shared with the index files of
``stiffmap sensor --index``.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..io import ALLOW_OUTSIDE_OPTION, leaves_directory
from .spec import SPEC_NAME

__all__ = ["ALLOW_OUTSIDE_OPTION", "campaign_file", "own_file"]


def campaign_file(
    root: Path, rel: str, key: str, item: str = "", *, allow_outside: bool = False, cache: dict | None = None
) -> Path:
    """The path of a file that ``campaign.toml`` names under ``key``, relative to ``root``.

    Parameters
    ----------
    root : Path
        The campaign directory.
    rel : str
        The name as written (or as a pattern gave it).
    key : str
        Where it is named, for the message: ``"camera.file"``, ``"images.loaded"``...
    item : str
        Which of the files the key names, e.g. ``"position 2, load 3, repeat 1"``.
    allow_outside : bool
        Accept names that lead outside the directory (``--allow-outside-paths``).
    cache : dict, optional
        Resolved folders, shared by the calls for one campaign
        (:func:`stiffmap.io.leaves_directory`).

    Raises
    ------
    InputError
        ``campaign.toml: key 'camera.file': '../cam.json' goes up with '..' (to /x/cam.json),
        outside the campaign directory; ...give --allow-outside-paths to read it anyway``,
        when the name leads outside the campaign directory and ``allow_outside`` is False.
    """
    if not allow_outside:
        how = leaves_directory(root, rel, cache)
        if how is not None:
            where = f"key {key!r}" + (f" ({item})" if item else "")
            raise InputError(
                f"{where}: {rel!r} {how}, outside the campaign directory; the files campaign.toml "
                f"names must stay inside it (give {ALLOW_OUTSIDE_OPTION} to read it anyway)",
                source=str(root / SPEC_NAME),
            )
    return root / rel


def own_file(root: Path, name: str, *, allow_outside: bool = False) -> str | None:
    """How a file stiffmap keeps in the campaign under a fixed name (``stiffmap.db``,
    ``truth.json``) leads outside it (a symbolic link), worded for a message; None when it
    stays in, or with ``allow_outside``.

    Returns
    -------
    str or None
        ``"stiffmap.db leads through a symbolic link to /x/y.db, outside the campaign directory"``.
    """
    if allow_outside:
        return None
    how = leaves_directory(root, name)
    return None if how is None else f"{name} {how}, outside the campaign directory"
