"""pycolmap, imported with curate's own signal handlers kept.

pycolmap installs glog's failure signal handler when it is imported: on SIGTERM it prints a native stack dump
(and during mapping it deadlocked, holding the run folder's lock). :func:`load` imports pycolmap and installs
curate's handlers again (:mod:`curate.core.signals`), where curate had installed them.
"""

from __future__ import annotations


def load():
    """The pycolmap module, with curate's signal handlers (re)installed after its import."""
    import pycolmap
    from curate.core import signals
    if signals.installed():
        signals.install()
    return pycolmap
