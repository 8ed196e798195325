"""Helpers shared by every layer of lfproc (foundations; imports nothing above ``lfproc.errors``).

One module per job: :mod:`.random` (``check_random_state``), :mod:`.progress` (progress bars),
:mod:`.validation` (option checks), :mod:`.parallel` (worker counts, Dask realignment),
:mod:`.jsonable`, :mod:`.hashing`, :mod:`.warn` (saturation/convergence warnings),
:mod:`.frozen` (read-only arrays of the core types), :mod:`.reprs` (short reprs),
:mod:`.stdio` (capturing output), :mod:`.zipfiles` (ZIP sniffing), :mod:`.deprecate` (renamed
keywords, option objects). Private to lfproc: import the
module you need, e.g. ``from lfproc._shared.random import check_random_state``.
"""
