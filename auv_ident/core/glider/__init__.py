"""A buoyancy-driven underwater glider in the vertical plane: its record of dives
(:mod:`.record`), its steady and dynamic flight model (:mod:`.flight`) and the calibration of
that model from the depth rate over several dives, with error bars (:mod:`.calibration`).

Self-contained: it uses the core's error types and the sandwich covariance of
:mod:`auv_ident.core.identification.uncertainty`, nothing of the 6-DOF model (a glider's flight
is a balance of buoyancy, lift and drag along the glide path, not the manoeuvring derivatives
of :mod:`auv_ident.core.model`)."""
