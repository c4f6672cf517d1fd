#!/usr/bin/env bash
# A Debian base image with Python made from Debian packages alone, for machines where the public
# image registry (python:3.11-slim) is unreachable but a Debian mirror is:
#   debootstrap -> tar -> docker import.
#
#   docker/base-image.sh [TAG]          (default squashcal-base:bookworm; needs root and debootstrap)
#   docker build --build-arg BASE_IMAGE=squashcal-base:bookworm -f docker/Dockerfile -t squashcal .
#
# Environment: SUITE (bookworm: Python 3.11), MIRROR (default: the first deb.debian.org-style URI
# of this machine's apt sources, else http://deb.debian.org/debian).
set -euo pipefail

TAG="${1:-squashcal-base:bookworm}"
SUITE="${SUITE:-bookworm}"
# Python, venv and pip for the application; certificates so pip can reach an https index.
PACKAGES="python3,python3-venv,python3-pip,ca-certificates"

if docker image inspect "$TAG" >/dev/null 2>&1; then
    echo "base image $TAG exists (docker rmi $TAG to make it anew)"
    exit 0
fi

default_mirror() {
    # the mirror apt already uses here (deb822 or one-line sources), so no other network is needed
    local uri
    uri=$(grep -rhoE '^(URIs:|deb) +[^ ]*debian/?( |$)' /etc/apt/sources.list /etc/apt/sources.list.d/ \
        2>/dev/null | head -1 | awk '{print $2}') || true
    echo "${uri:-http://deb.debian.org/debian}"
}
MIRROR="${MIRROR:-$(default_mirror)}"

command -v debootstrap >/dev/null || {
    echo "debootstrap is missing: apt-get install -y debootstrap" >&2
    exit 1
}

ROOT=$(mktemp -d /tmp/squashcal-rootfs.XXXXXX)
trap 'rm -rf "$ROOT"' EXIT
echo "debootstrap $SUITE from $MIRROR into $ROOT"
debootstrap --variant=minbase --include="$PACKAGES" "$SUITE" "$ROOT" "$MIRROR"
# apt lists and caches are not needed in an image that pip installs into
rm -rf "$ROOT"/var/lib/apt/lists/* "$ROOT"/var/cache/apt/archives/*.deb
tar -C "$ROOT" -c . | docker import \
    --change 'ENV LANG=C.UTF-8' \
    --change 'CMD ["/bin/bash"]' \
    - "$TAG"
echo "built $TAG"
