#!/bin/sh
# The Debian packages binpick's tests use beyond PyPI: Aravis with its GObject introspection data
# (the GigE Vision source) and aravis-tools (arv-fake-gv-camera-0.8, the fake GigE Vision camera
# the tests stream from), and the headers PyGObject builds against. Run as root, or with sudo.
# On a system without apt-get it says so and does nothing: the GigE Vision tests then skip.
set -e
PACKAGES="aravis-tools gir1.2-aravis-0.8 libgirepository1.0-dev libcairo2-dev pkg-config"
if ! command -v apt-get >/dev/null 2>&1; then
  echo "system-packages: no apt-get here; install Aravis 0.8 (aravis-tools, its GObject introspection data) by hand" >&2
  exit 0
fi
SUDO=""
if [ "$(id -u)" != "0" ]; then SUDO="sudo"; fi
if dpkg -s $PACKAGES >/dev/null 2>&1; then exit 0; fi
$SUDO apt-get update -q >/dev/null
$SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends $PACKAGES >/dev/null
echo "system-packages: installed $PACKAGES"
