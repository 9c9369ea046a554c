"""Imported last by the forkserver (:mod:`pbdkit.sim._forkserver`): moves every object loaded so far
to the garbage collector's permanent generation (:func:`gc.freeze`).

The collector then never walks the preloaded modules again: not in the workers forked from the
server (whose full collections during a trial get cheaper, and leave the shared pages
unwritten), nor when the server exits, where the final collection of what it preloaded took
about half a second, during which a shell pipeline of ``pbdkit evaluate --workers`` waited.
"""

import gc

gc.freeze()
