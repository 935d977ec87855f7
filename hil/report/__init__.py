"""What a person reads about a run: the certificate as HTML and PDF with a plot per
protocol (:mod:`hil.report.documents`), the plots and raw data for Allure, and the
operator's console. Nothing is imported here: a calibration that writes no documents
does not load matplotlib."""
