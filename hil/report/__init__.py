"""What a person reads about a run: the certificate as HTML and PDF with a plot per
protocol, the plots and raw data for Allure, and the operator's console."""

from hil.report.documents import certificate_file, write_documents

__all__ = ["certificate_file", "write_documents"]
