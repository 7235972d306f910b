"""Hysteresis cores, one module per core, on one contract (:mod:`~piezohyst.model.cores.base`).

==============  ==========================================================
``base``        the :class:`~piezohyst.model.cores.base.Core` contract, the registry,
                :class:`~piezohyst.model.cores.base.Region`, the packed cores' base
``play``        Prandtl-Ishlinskii play operators (PI): the core, its regressor
                columns, states, identification, the growth proxy
``preisach``    the Preisach core (Everett function, reversal memory)
``duhem``       the Duhem core (slopes over voltage and output)
``boucwen``     the Bouc-Wen core
``_inmemory``   what the cores fitted on a record in memory share
``c/``          the compensator steps in C (``play.c``, ``packed.c``)
==============  ==========================================================

The per-sample loops are numba kernels: play operators in
:mod:`piezohyst._kernels`, the packed cores in :mod:`piezohyst._kernels.packed`.
"""
