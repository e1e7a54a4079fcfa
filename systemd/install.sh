#!/usr/bin/env bash
# Install the ghnerf daemon as a systemd service on the device, from this checkout.
#
#   sudo systemd/install.sh                      # /opt/ghnerf, enable and start ghnerf.service
#   sudo systemd/install.sh --prefix /srv/ghnerf --no-start
#   systemd/install.sh --destdir /tmp/stage      # stage the files only (an image build; no root)
#
# What it does: a virtual environment with the runtime only (no PyTorch) at PREFIX/venv, pinned by
# constraints.txt; the models and docs under PREFIX; the unit file, the udev rules and, when none is
# there yet, /etc/ghnerf/daemon.json (an existing config is never overwritten); a system user
# `ghnerf` in plugdev and dialout; the config checked with --validate-config; then systemd and
# udev reloaded and the service enabled and started. docs/daemon.md has the details.
set -euo pipefail

PREFIX=/opt/ghnerf
DESTDIR=
PYTHON=${PYTHON:-python3.11}
START=1
VENV=1

die() { echo "install.sh: error: $*" >&2; exit 2; }
usage() { sed -n '2,13p' "$0" | sed 's/^# \{0,1\}//'; exit "${1:-0}"; }

while [ $# -gt 0 ]; do
    case "$1" in
        --prefix) [ $# -ge 2 ] || die "--prefix needs a folder"; PREFIX=$2; shift 2 ;;
        --destdir) [ $# -ge 2 ] || die "--destdir needs a folder"; DESTDIR=$2; shift 2 ;;
        --python) [ $# -ge 2 ] || die "--python needs an interpreter"; PYTHON=$2; shift 2 ;;
        --no-start) START=0; shift ;;
        -h|--help) usage 0 ;;
        *) echo "install.sh: error: unknown option $1" >&2; usage 2 ;;
    esac
done
case "$PREFIX" in /*) ;; *) die "--prefix must be an absolute path, got $PREFIX" ;; esac
case "$PREFIX" in *[!A-Za-z0-9/._-]*) die "--prefix may hold only letters, digits and / . _ -, got $PREFIX" ;; esac

REPO=$(cd "$(dirname "$0")/.." && pwd)
ROOT=${DESTDIR%/}
if [ -n "$DESTDIR" ]; then
    # A virtual environment records its own absolute path: it cannot be built in a staging folder.
    VENV=0
    START=0
    mkdir -p "$DESTDIR"
elif [ "$(id -u)" != 0 ]; then
    die "run as root (or pass --destdir DIR to stage the files without installing them)"
fi
[ -f "$REPO/models/model_card.json" ] || die "no model in $REPO/models (make model builds it)"
[ -f "$REPO/constraints.txt" ] || die "$REPO/constraints.txt is missing: run from a full checkout"

echo "installing the ghnerf daemon from $REPO into ${ROOT}${PREFIX}"
install -d "$ROOT$PREFIX" "$ROOT$PREFIX/docs" "$ROOT/etc/ghnerf" "$ROOT/etc/systemd/system" "$ROOT/etc/udev/rules.d"

# Models: replaced as a whole, so no graph of an older model is left beside the new ones.
rm -rf "$ROOT$PREFIX/models.new"
cp -R "$REPO/models" "$ROOT$PREFIX/models.new"
rm -rf "$ROOT$PREFIX/models"
mv "$ROOT$PREFIX/models.new" "$ROOT$PREFIX/models"
cp "$REPO"/docs/*.md "$ROOT$PREFIX/docs/"

if [ -z "$DESTDIR" ]; then
    getent group plugdev >/dev/null || groupadd --system plugdev
    getent group dialout >/dev/null || groupadd --system dialout
    if ! id ghnerf >/dev/null 2>&1; then
        useradd --system --home-dir /var/lib/ghnerf --no-create-home --shell /usr/sbin/nologin \
            --user-group --groups plugdev,dialout ghnerf
    fi
fi

if [ "$VENV" = 1 ]; then
    "$PYTHON" -m venv --clear "$PREFIX/venv"  # rebuilt: an upgrade may change the interpreter
    "$PREFIX/venv/bin/python" -m pip install --quiet --upgrade "pip>=24"
    # The runtime only: onnxruntime, OpenCV, depthai, pyserial, pyusb, numpy (no [training] extra).
    "$PREFIX/venv/bin/python" -m pip install --quiet -c "$REPO/constraints.txt" "$REPO"
    # The venv links to the interpreter it was made from: one under a private home (pyenv in
    # /root) installs fine but the service user cannot start it.
    runuser -u ghnerf -- "$PREFIX/venv/bin/python" -c "import firmware_host.daemon" \
        || die "the service user ghnerf cannot run $PREFIX/venv/bin/python (it is $(readlink -f "$PREFIX/venv/bin/python")); pass --python with an interpreter every user can run, e.g. --python /usr/bin/python3.11"
fi

sed "s|/opt/ghnerf|$PREFIX|g" "$REPO/systemd/ghnerf.service" > "$ROOT/etc/systemd/system/ghnerf.service"
chmod 0644 "$ROOT/etc/systemd/system/ghnerf.service"
install -m 0644 "$REPO/systemd/60-ghnerf.rules" "$ROOT/etc/udev/rules.d/60-ghnerf.rules"
if [ -e "$ROOT/etc/ghnerf/daemon.json" ]; then
    echo "kept the existing $ROOT/etc/ghnerf/daemon.json"
else
    sed "s|/opt/ghnerf|$PREFIX|g" "$REPO/systemd/daemon.json" > "$ROOT/etc/ghnerf/daemon.json"
    chmod 0644 "$ROOT/etc/ghnerf/daemon.json"
    echo "wrote $ROOT/etc/ghnerf/daemon.json: set its rig.url and sinks for this rig (docs/daemon.md)"
fi

if [ "$VENV" = 1 ]; then
    runuser -u ghnerf -- "$PREFIX/venv/bin/ghnerf-daemon" --config /etc/ghnerf/daemon.json --validate-config >/dev/null \
        || die "/etc/ghnerf/daemon.json does not validate (message above); fix it and run install.sh again"
fi

if [ "$START" = 1 ]; then
    systemctl daemon-reload
    udevadm control --reload-rules
    udevadm trigger --subsystem-match=usb
    systemctl enable ghnerf.service
    systemctl restart ghnerf.service
    systemctl --no-pager --lines=5 status ghnerf.service || true
else
    echo "not started; on the device: systemctl daemon-reload && systemctl enable --now ghnerf.service"
fi
