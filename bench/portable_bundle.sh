#!/usr/bin/env bash
# Packs the built ltmapper with every shared library `ldd` lists into one xz tarball that runs on
# another x86-64 Linux machine without installing anything (a lent many-core machine, issue 18):
#   bench/portable_bundle.sh [BIN] OUT.tar.xz
#   there: mkdir b && tar -C b -xJf OUT.tar.xz && b/ltmapper --version   # b/ltmapper is a launcher
# The launcher runs the binary through the carried dynamic loader with the carried libraries only.
set -euo pipefail
BIN=${2:+$1}; BIN=${BIN:-build/apps/ltmapper}
OUT=${2:-${1:?usage: bench/portable_bundle.sh [BIN] OUT.tar.xz}}
DIR=$(mktemp -d); trap 'rm -rf "$DIR"' EXIT
mkdir -p "$DIR/lib"
cp "$BIN" "$DIR/lib/ltmapper.bin"
ldd "$BIN" | awk '/=>/ && $3 ~ /^\// {print $3} $1 ~ /^\/.*ld-linux/ {print $1}' | sort -u |
  while read -r lib; do cp -L "$lib" "$DIR/lib/"; done
LOADER=$(cd "$DIR/lib" && ls ld-linux-*.so.*)
cat > "$DIR/ltmapper" <<LAUNCH
#!/bin/sh
here=\$(dirname "\$(readlink -f "\$0")")
exec "\$here/lib/$LOADER" --library-path "\$here/lib" "\$here/lib/ltmapper.bin" "\$@"
LAUNCH
chmod +x "$DIR/ltmapper"
tar -C "$DIR" -cJf "$OUT.tmp" . && mv "$OUT.tmp" "$OUT"
echo "$OUT: $(ls "$DIR/lib" | wc -l) files, $(du -h "$OUT" | cut -f1)"
