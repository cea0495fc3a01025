"""Known-answer problems (BENCHMARKS.md): builders that return a ready Simulation with its exact
solution and error measures, shared by the tests, the demos and the benchmark suite.

    elastic            V1 vibrating bar, V2 small-strain column (explicit and DM-GC), L2 discs
    column             V2 large-strain (AMPLE) column
    mms                V3 manufactured solution
    cylinder           thick cylinder (Lame, Hill) on axisymmetric grids
    absorbing_column   W1 pulse in a column on fixed/viscous/viscoelastic bases
    soil_column        P1 site response of a soil column
    sudden_column      PEERS.md column under suddenly applied gravity (CB-Geo's benchmark)
    friction           blocks on rough bases and rigid inclines
    rotating_disc      a rigidly spinning elastic disc (angular momentum)
    localisation       softening shear layer and strip footing (regularisation)
    footing            Prandtl's smooth strip footing on Tresca soil (F-bar)
    granular_collapse  dry granular column on a rough base against Lube et al.'s (2005) laws
    softening_slope    a softening Mohr-Coulomb slope that fails and runs out (run-out vs h)
    slope_stability    Bishop's limit-equilibrium factor of safety (the L4 slope's reference)
"""
