"""The paper's cases, the reproduce pipeline and REPORT.md."""
