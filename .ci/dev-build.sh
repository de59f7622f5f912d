#!/usr/bin/env bash
# Rebuild binpick._core for an editable install (pip install -e . once first): an optimised
# build without LTO, copied over the module the editable install loads. For development only.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --profile fast -p binpick-python --message-format=short "$@"
suffix=$(python3 -c 'import sysconfig; print(sysconfig.get_config_var("EXT_SUFFIX"))')
# Copy then rename: replacing the file in place would corrupt it under running processes.
cp target/fast/lib_core.so "python/binpick/.core.tmp${suffix}"
mv -f "python/binpick/.core.tmp${suffix}" "python/binpick/_core${suffix}"
echo "binpick._core rebuilt (profile fast)"
