"""Simulation the user asks for: dry runs of a scheme on the simulated bench (sim_devices) and
Monte Carlo repetitions of simulate -> estimate.  The only station package that imports sim_devices
(besides the CLI's ``sim serve``)."""
