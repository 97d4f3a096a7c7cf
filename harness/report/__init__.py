"""Reports: one self-contained HTML page per suite run (cases, error maps, convergence, shadow rays, strategies),
with every number in report.json and a short summary.md; and convergence studies. See docs/report.md."""

from harness.report.build import ReportOptions, load_results, write_convergence_report, write_suite_report

__all__ = ["ReportOptions", "load_results", "write_convergence_report", "write_suite_report"]
