"""What the records become for a reader: the paper's tables
(:mod:`~bench.reporting.tables`), convergence, residual and adaptation plots
(:mod:`~bench.reporting.plots`), and the leaderboard
(:mod:`~bench.reporting.leaderboard`). All of it is a pure function of the
records."""
