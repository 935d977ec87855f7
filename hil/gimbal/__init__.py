"""A gimbal as the unit: a gimbal profile names its axes (each an axis profile), and
``gimbal-hil calibrate --gimbal`` calibrates each axis under the gimbal's one serial and
issues one gimbal certificate with one verdict (:mod:`hil.gimbal.run`)."""
