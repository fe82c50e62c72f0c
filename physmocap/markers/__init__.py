"""Optical markers: labelled marker recordings to the actor's joint centres.

* :mod:`.recording`: :class:`MarkerRecording`, what a C3D or TRC file holds (labels,
  positions in metres, validity), and the up-axis guess.
* :mod:`.markerset`: marker sets: which label plays which anatomical role (built-in
  aliases for the CMU, Vicon Plug-in Gait, Helen Hayes, Qualisys and OptiTrack sets),
  detection from the labels, user TOML files.
* :mod:`.joints`: joint centres from the roles (regression: Harrington 2007 hip centres,
  lateral markers offset medially by a joint half-width, wrist and head centroids), then a
  positional :class:`~physmocap.motion.Motion` the retargeter consumes unchanged.

* :mod:`.sides`: the side of markers whose labels do not say it, from where they are.
* :mod:`.functional`: segment frames (Kabsch), functional joint centres (SCoRE, sphere fit)
  where the motion can place them, fixed segment lengths.
* :mod:`.solve`: the actor calibration (:func:`~.solve.calibrate_actor`) and marker-driven IK
  (:func:`~.solve.solve_markers`, ``physmocap solve``).
* :mod:`.stream`: the streaming solve (calibrate once, one frame at a time); :mod:`.replay`:
  ``physmocap replay`` on marker recordings.

Readers: :mod:`physmocap.sources.c3d` (ezc3d), :mod:`physmocap.sources.trc`, and marker MCAP
(:func:`physmocap.sources.mcap.read_mcap_markers`).
"""
