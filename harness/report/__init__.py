"""Reports: one self-contained HTML page per suite run (cases, error maps, and the run's studies: convergence, shadow
rays, strategies), with every number in report.json and a short summary.md; and the page of a convergence study.
The report formats results and renders nothing (the studies are computed by harness run:
harness.studies.suite_studies). See docs/report.md."""

from harness.report.build import ReportOptions, load_results, write_convergence_report, write_suite_report

__all__ = ["ReportOptions", "load_results", "write_convergence_report", "write_suite_report"]
