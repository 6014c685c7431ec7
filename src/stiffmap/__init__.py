"""stiffmap: measure, model and map the stiffness and static positioning error of robots.

Importing :mod:`stiffmap` is light: it pulls in no numerical or plotting library.
Import the layer you need (``stiffmap.geometry``, ``stiffmap.identify``, ...).
Conventions (units N-mm-MPa, frames ``a2b``, pixels, orientation) are in
``docs/conventions.md``.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
