"""Running suites: the case format, budgets, judging a case, scheduling on executors, run state, baselines, calibration, JUnit."""
