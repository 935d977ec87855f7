"""Where a gimbal certificate lives and what it declares itself: ``hil.gimbal`` writes
it; the comparison and the results store, below it, read it."""

GIMBAL_SCHEMA = "gimbal-hil/gimbal-certificate/v1"
GIMBAL_FILE = "gimbal-certificate.json"  # in the gimbal's folder; .txt, .html, .pdf beside it
