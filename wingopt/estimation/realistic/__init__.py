"""Load identification on real membranes (issue 11): nonlinear (Berger) model, prestrain and damping
as unknowns, gust-following loads, model-adequacy flag and a misfit-inflated band."""
