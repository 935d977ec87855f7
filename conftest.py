"""Repo-level pytest wiring only: what is not collected. The gimbal-hil plugin loads through
its ``pytest11`` entry point; test-only settings (hypothesis profiles) live in tests/."""

collect_ignore = ["benchmarks", "docs", "build"]
