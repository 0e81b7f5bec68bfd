#!/usr/bin/env bash
# Builds the web front end of `edrnr serve` (web/ -> web/dist/) with the npm
# packages pinned in web/package-lock.json (npm ci), so the same lock file
# gives the same files. Node is needed only here, never at run time.
#
# Skips the work when web/dist is newer than every source and the lock file.
# Exit status 0 when web/dist is up to date; 1 when it cannot be built.
# Options: --force (rebuild), --if-possible (exit 0 with a message when npm is
# missing or the build fails, for scripts/build.sh).
set -euo pipefail
cd "$(dirname "$0")/../web"
force=0 soft=0
for a in "$@"; do
  case "$a" in
    --force) force=1 ;;
    --if-possible) soft=1 ;;
    *) echo "build-web: unknown option '$a' (known: --force, --if-possible)" >&2; exit 2 ;;
  esac
done
give_up() {
  if [ "$soft" = 1 ]; then
    echo "build-web: $1; 'edrnr serve' needs the front end (run scripts/setup.sh, then scripts/build-web.sh)" >&2
    exit 0
  fi
  echo "build-web: $1" >&2
  exit 1
}
command -v npm >/dev/null || give_up "npm not found (scripts/setup.sh installs nodejs and npm)"

# One build at a time in this checkout.
exec 9>.build-web.lock
flock 9

newest_source=$(find index.html vite.config.ts tsconfig.json package.json package-lock.json src -newer dist/index.html 2>/dev/null | head -1 || true)
if [ "$force" = 0 ] && [ -f dist/index.html ] && [ -z "$newest_source" ]; then
  echo "build-web: web/dist is up to date"
  exit 0
fi
# Reinstall the packages when the lock file changed (or they are missing).
if [ ! -f node_modules/.package-lock.json ] || [ package-lock.json -nt node_modules/.package-lock.json ]; then
  echo "build-web: installing the npm packages of web/package-lock.json"
  # npm ci refuses a lock file that lacks the optional packages of other
  # platforms (a lock written against a registry mirror that does not carry
  # them); npm install then installs the same locked versions and hashes.
  if ! ci_log=$(npm ci --no-audit --no-fund --loglevel=error 2>&1); then
    echo "build-web: npm ci refused the lock file ($(echo "$ci_log" | grep -m1 -o 'Missing: [^ ]*' || echo "see below")); installing its versions with npm install"
    npm install --no-audit --no-fund --loglevel=error || { echo "$ci_log" >&2; give_up "npm install failed (is the npm registry reachable?)"; }
  fi
fi
echo "build-web: building web/dist"
npm run --silent build || give_up "the front end build failed"
echo "build-web: web/dist is up to date"
