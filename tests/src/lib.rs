//! Test-only package: the integration scenarios live under `it/`.
