"""`wolfcal venue`: the head camera's recalibration between two games as one session.

Modules, one job each:
- `options`: what a session is asked to do, checked before anything opens;
- `plans`: the poses of the feet views, planned once per robot config and kept in the cache;
- `state`: the session folder (state file, capture parts), so that an interrupted session resumes;
- `motion`: driving the servos through poses fast and safely, one sample per pose;
- `check`: fit, cross-validation, held-out floor views, verdict and deploy files;
- `session`: the whole session, phase by phase, with what is said to the operator.
"""
