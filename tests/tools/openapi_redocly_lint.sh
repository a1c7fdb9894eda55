#!/usr/bin/env bash
# Lints api/openapi.yaml with the Redocly CLI pinned in tools/redocly
# (package.json + package-lock.json; scripts/install-deps.sh runs npm ci
# there), with the repository's redocly.yaml (recommended-strict: every
# problem is an error) and .redocly.lint-ignore.yaml. Fails when the CLI is
# missing or is not the pinned version: install-deps.sh always installs it.
# Usage: openapi_redocly_lint.sh [SOURCE_DIR]
set -euo pipefail
src=${1:-$(cd "$(dirname "$0")/../.." && pwd)}
tool=$src/tools/redocly
cli=$tool/node_modules/.bin/redocly
want=$(sed -n 's/.*"@redocly\/cli": *"\([^"]*\)".*/\1/p' "$tool/package.json")
if [[ ! -x "$cli" ]]; then
    echo "FAIL: $cli is not installed: run scripts/install-deps.sh (npm ci in tools/redocly)"
    exit 1
fi
have=$("$cli" --version 2>/dev/null || true)
if [[ "$have" != "$want" ]]; then
    echo "FAIL: tools/redocly has Redocly CLI '$have', package.json pins '$want': run scripts/install-deps.sh"
    exit 1
fi
cd "$src"
# No usage data sent, no update notice.
export REDOCLY_TELEMETRY=off REDOCLY_SUPPRESS_UPDATE_NOTICE=true
exec "$cli" lint --config redocly.yaml api/openapi.yaml
