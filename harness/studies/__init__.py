"""Studies that render: convergence, noise against shadow rays, strategies, stress, bench."""
