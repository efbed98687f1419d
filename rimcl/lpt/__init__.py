"""3-D Lagrangian particle tracking (LPT) through the refractive-index field.

Several cameras look at a volume of tracers through the exit face ``x1 = x_end`` and its
window. Stages: :mod:`~rimcl.lpt.config` (the ``[rig]``, ``[illumination]`` and ``[lpt]``
scene sections, presets), :mod:`~rimcl.lpt.rig` (camera geometry: pinhole plus window),
:mod:`~rimcl.lpt.views` (each tracer's rays traced to each camera),
:mod:`~rimcl.lpt.images` (rendered, digitised and located tracer images, Mie weights),
:mod:`~rimcl.lpt.calibration` (target, pinhole/DLT and Soloff fits, lines of sight,
triangulation), :mod:`~rimcl.lpt.flow` (volume velocity, tracer tracks),
:mod:`~rimcl.lpt.run` (the whole chain, statistics, case files) and
:mod:`~rimcl.lpt.files` (case files and datasets for LPT codes).
"""
