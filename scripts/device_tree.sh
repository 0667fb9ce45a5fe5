#!/usr/bin/env bash
# Fit the working tree into a device call. The device tool sends tracked and untracked-not-ignored files plus
# the carried folders, 64 MiB in all; the tracked tree alone is over 62 MiB (the paper models), so a call that
# carries wheels (scripts/gpu_bench.sh --prepare: 11.8 MB) or a model must leave some tracked files behind.
# `shed` takes paths out of the index and ignores them (.git/info/exclude), leaving the files on disk;
# `restore` puts them back in the index exactly as they were committed. Nothing is committed either way.
#
#   scripts/device_tree.sh size [CARRY…]     bytes that would travel (tracked + untracked-not-ignored + CARRY)
#   scripts/device_tree.sh shed PATH…        e.g. assets/paper-corner-cubes assets/paper-snake assets/paper-pits
#   scripts/device_tree.sh restore           after the call (also after a failed one)
set -euo pipefail
cd "$(dirname "$0")/.."
exclude=$(git rev-parse --git-path info/exclude)
state=$(git rev-parse --git-path device_tree_shed)

travelling_bytes() {
    { git ls-files -z; git ls-files -z --others --exclude-standard; } | du -cb --files0-from=- | tail -1 | cut -f1
}

case "${1:-}" in
size)
    shift
    total=$(travelling_bytes)
    for carried in "$@"; do total=$((total + $(du -sb "$carried" | cut -f1))); done
    echo "$total bytes ($((total / 1048576)) MiB of 64 MiB)"
    ;;
shed)
    shift
    [[ $# -gt 0 ]] || { echo "device_tree.sh shed: name the paths to leave behind" >&2; exit 2; }
    for path in "$@"; do
        [[ -n "$(git ls-files -- "$path")" ]] || { echo "device_tree.sh: $path: no tracked files" >&2; exit 2; }
    done
    mkdir -p "$(dirname "$exclude")"
    for path in "$@"; do
        git rm -r -q --cached -- "$path"
        echo "/${path%/}/" >>"$exclude"  # gitignore has no trailing comments: the pattern stands alone
        echo "$path" >>"$state"
    done
    echo "left behind: $*; now $(travelling_bytes) bytes travel (restore with: scripts/device_tree.sh restore)"
    ;;
restore)
    [[ -f "$state" ]] || { echo "device_tree.sh: nothing was shed"; exit 0; }
    mapfile -t paths <"$state"
    git reset -q -- "${paths[@]}"
    patterns=$(printf '/%s/\n' "${paths[@]%/}")
    grep -v -x -F "$patterns" "$exclude" >"$exclude.tmp" || true
    mv "$exclude.tmp" "$exclude"
    rm "$state"
    echo "restored: ${paths[*]}"
    ;;
*)
    echo "usage: scripts/device_tree.sh size [CARRY…] | shed PATH… | restore" >&2
    exit 2
    ;;
esac
