"""Shape-function families (the "shape" stage): standard (the Lagrange basis of the particle's
cell, Simulation(shape="mpm")), gimp ("ugimp"/"cpgimp"), cpdi ("cpdi1"/"cpdi2"), gauss_gimp
("gauss") and cmpm (the composite basis of the DM-GC integrators)."""
