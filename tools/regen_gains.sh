#!/usr/bin/env bash
# Regenerate the committed tables of every shipped example (byte-for-byte reproducible).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
for f in examples/*.toml; do
  "$root/.venv/bin/stospline" design "$f" --out gains/
done
