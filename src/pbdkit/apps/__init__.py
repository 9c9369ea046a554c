"""Applications on top of the library: the ``pbdkit`` command (:mod:`.cli`), its ``demo``
(:mod:`.demo`) and ``study`` (:mod:`.study`) jobs, the paper's figures (:mod:`.plots`) and the
HTML report (:mod:`.report`). The top layer: nothing below imports it."""
