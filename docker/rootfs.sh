# shellcheck shell=bash
# Sourced by docker/prove_image.sh and docker/prove_bare.sh (not run): a minimal Debian (or Ubuntu) root made from
# its archive with debootstrap, and commands run inside it with chroot, in a private mount namespace.
#
# The archive, all optional (Debian 12 by default; Ubuntu 24.04: docs/install.md, "Proving the install"):
#   BARE_SUITE       bookworm                             the release (debootstrap's SUITE)
#   BARE_MIRROR      http://deb.debian.org/debian         its archive
#   BARE_COMPONENTS  main                                 comma-separated (Ubuntu: main,universe)
#   BARE_SECURITY    http://deb.debian.org/debian-security   the archive of SUITE-security ("" for none)
#   BARE_SCRIPT      (debootstrap's own for the suite)    a script of /usr/share/debootstrap/scripts to use instead
#   BARE_KEYRING     (debootstrap's default)              the archive's keyring
#   FLEXSHEET_IMAGE_WORK  /var/tmp/flexsheet-image        where roots, logs and buildah's storage go
#
# This machine's network reaches PyPI through a TLS-intercepting proxy: its CA lies in /usr/local/share/ca-certificates
# and pip is told so in its configuration. A root made here gets the same (mirror_host_config), or pip could not
# reach the index; nothing of it goes into the image (docker/prove_image.sh mounts it for the build only).
BARE_SUITE=${BARE_SUITE:-bookworm}
BARE_MIRROR=${BARE_MIRROR:-http://deb.debian.org/debian}
BARE_COMPONENTS=${BARE_COMPONENTS:-main}
BARE_SECURITY=${BARE_SECURITY-http://deb.debian.org/debian-security}
BARE_SCRIPT=${BARE_SCRIPT:-}
BARE_KEYRING=${BARE_KEYRING:-}
# shellcheck disable=SC2034  # WORK and PROG: the sourcing scripts' settings too
WORK=${FLEXSHEET_IMAGE_WORK:-/var/tmp/flexsheet-image}
PROG=${PROG:-rootfs}

log() { echo "[$PROG] $*"; }
die() { echo "[$PROG] ERROR: $*" >&2; exit 1; }

# need CMD PACKAGE ...: apt-get installs each package whose command is missing
need() {
  local missing=() cmd pkg
  while [ $# -ge 2 ]; do
    cmd=$1 pkg=$2; shift 2
    command -v "$cmd" >/dev/null 2>&1 || missing+=("$pkg")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  command -v apt-get >/dev/null 2>&1 || die "missing ${missing[*]} and no apt-get to install them"
  [ "$(id -u)" -eq 0 ] || die "missing ${missing[*]}: run as root"
  log "apt-get install ${missing[*]}"
  apt-get -o DPkg::Lock::Timeout=600 install -y -qq --no-install-recommends "${missing[@]}" >/dev/null \
    || die "apt-get install ${missing[*]} failed"
}

# make_rootfs ROOT [PACKAGES]: a fresh minimal root of BARE_SUITE in ROOT (PACKAGES comma-separated, added), with
# apt sources for the suite, its updates and its security archive
make_rootfs() {
  local root=$1 include=${2:-} comps
  if [ -z "$root" ] || [ "$root" = / ]; then die "make_rootfs: bad root '$root'"; fi
  remove_root "$root"
  mkdir -p "$root"
  log "debootstrap --variant=minbase $BARE_SUITE $root $BARE_MIRROR${include:+ (+ $include)}"
  local args=(--variant=minbase --components="$BARE_COMPONENTS")
  [ -n "$BARE_KEYRING" ] && args+=(--keyring="$BARE_KEYRING")
  [ -n "$include" ] && args+=(--include="$include")
  if ! debootstrap "${args[@]}" "$BARE_SUITE" "$root" "$BARE_MIRROR" ${BARE_SCRIPT:+"$BARE_SCRIPT"} \
      >"$root.debootstrap.log" 2>&1; then
    tail -n 20 "$root.debootstrap.log" >&2
    die "debootstrap failed (log: $root.debootstrap.log)"
  fi
  comps=${BARE_COMPONENTS//,/ }
  {
    echo "deb $BARE_MIRROR $BARE_SUITE $comps"
    echo "deb $BARE_MIRROR $BARE_SUITE-updates $comps"
    [ -z "$BARE_SECURITY" ] || echo "deb $BARE_SECURITY $BARE_SUITE-security $comps"
  } >"$root/etc/apt/sources.list"
}

# the host's pip configuration files that exist, one a line
pip_config_files() {
  local f
  for f in /etc/pip.conf /etc/xdg/pip/pip.conf "$HOME/.config/pip/pip.conf" "$HOME/.pip/pip.conf" \
           ${PIP_CONFIG_FILE:+"$PIP_CONFIG_FILE"}; do
    [ -f "$f" ] && echo "$f"
  done
  return 0
}

# the existing absolute paths that the host's pip configuration names (cert, constraint, find-links, file://
# indexes: for DIR/simple, DIR, whose pages link to DIR/files), in its files and PIP_* variables, one a line
pip_config_paths() {
  local f
  {
    while IFS= read -r f; do sed -n 's/^[^=#;[]*=\s*//p' "$f"; done < <(pip_config_files)
    env | sed -n 's/^PIP_[A-Z_]*=//p'
  } | tr '[:blank:]' '\n' | sed -e "s/^['\"]//" -e "s/['\"]$//" -e 's|^file://||' | grep '^/' | sort -u \
    | sed 's|/simple/*$||' | sort -u | while IFS= read -r f; do [ -e "$f" ] && echo "$f"; done
  return 0
}

# mirror_host_config ROOT: resolv.conf, the local CAs (and the CA bundle made from them), the pip configuration
# and the files it names, copied into ROOT (the folders it names are bind-mounted by in_root)
mirror_host_config() {
  local root=$1 f dest
  cp -L /etc/resolv.conf "$root/etc/resolv.conf"
  if [ -d /usr/local/share/ca-certificates ]; then
    mkdir -p "$root/usr/local/share/ca-certificates"
    cp -a /usr/local/share/ca-certificates/. "$root/usr/local/share/ca-certificates/"
  fi
  while IFS= read -r f; do
    dest=$f
    case "$f" in "$HOME"/*) dest=/root/${f#"$HOME"/};; esac
    mkdir -p "$root$(dirname "$dest")"
    cp -L "$f" "$root$dest"
  done < <(pip_config_files)
  while IFS= read -r f; do
    [ -f "$f" ] || continue
    mkdir -p "$root$(dirname "$f")"
    cp -L "$f" "$root$f"
  done < <(pip_config_paths)
}

# the variables passed into the root: pip's, npm's, the proxies and the CA bundles named by the environment
host_env() {
  env | grep -E '^(PIP_[A-Z_]+|npm_config_[a-z_]+|(https?|no|all)_proxy|(HTTPS?|NO|ALL)_PROXY|NODE_EXTRA_CA_CERTS|SSL_CERT_FILE|SSL_CERT_DIR|REQUESTS_CA_BUNDLE|CURL_CA_BUNDLE)=' \
    || true
}

# in_root ROOT COMMAND: runs the bash command line COMMAND in ROOT as root, with chroot, in a private mount
# namespace (unshare -m): /proc, /sys, /dev and the pip configuration's folders bind-mounted, every mount undone
# on exit (also on failure). A clean environment: HOME=/root, the usual PATH, and host_env. Returns its exit code.
in_root() {
  local root=$1 cmd=$2 dirs=() envs=() f
  while IFS= read -r f; do [ -d "$f" ] && dirs+=("$f"); done < <(pip_config_paths)
  while IFS= read -r f; do envs+=("$f"); done < <(host_env)
  # the namespace's own script: its mounts are private, and the trap unmounts them in reverse order
  # shellcheck disable=SC2016
  unshare --mount --propagation private -- bash -c '
    set -u
    root=$1 cmd=$2 ndirs=$3; shift 3
    dirs=("${@:1:$ndirs}"); envs=("${@:$((ndirs + 1))}")
    mounted=()
    undo() {
      local i
      for ((i = ${#mounted[@]} - 1; i >= 0; i--)); do
        umount -R "${mounted[i]}" 2>/dev/null || umount -R -l "${mounted[i]}" || echo "umount ${mounted[i]} failed" >&2
      done
    }
    trap undo EXIT
    bind() {   # bind SOURCE TARGET [ro]
      mkdir -p "$root$2" || exit 90
      mount --rbind "$1" "$root$2" || { echo "mount --rbind $1 $root$2 failed" >&2; exit 90; }
      mounted+=("$root$2")
      mount --make-rslave "$root$2"
      [ "${3:-}" = ro ] && mount -o remount,bind,ro "$root$2"
      return 0
    }
    bind /proc /proc; bind /sys /sys; bind /dev /dev
    for d in ${dirs[@]+"${dirs[@]}"}; do bind "$d" "$d" ro; done
    chroot "$root" /usr/bin/env -i HOME=/root LANG=C.UTF-8 TERM=dumb DEBIAN_FRONTEND=noninteractive \
      PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin ${envs[@]+"${envs[@]}"} \
      /bin/bash -c "$cmd"
  ' in_root "$root" "$cmd" "${#dirs[@]}" ${dirs[@]+"${dirs[@]}"} ${envs[@]+"${envs[@]}"}
}

# mounts_under DIR: how many of this namespace's mounts lie in DIR (0 after in_root)
mounts_under() {
  awk -v d="$1/" 'index($5 "/", d) == 1 {n++} END {print n + 0}' /proc/self/mountinfo
}

# remove_root ROOT: deletes a root made here, refusing while anything is mounted in it
remove_root() {
  local root=$1
  [ -e "$root" ] || return 0
  [ "$(mounts_under "$root")" -eq 0 ] || die "$root still has mounts: not removed (findmnt -R $root)"
  rm -rf --one-file-system "$root"
}

# export_source DEST REF: the checkout's tracked files into DEST: REF a commit (git archive), or "worktree": the
# tracked files as they are now in the working tree (git ls-files); never .venv, out/ or other untracked files
export_source() {
  local dest=$1 ref=$2 top
  top=$(git rev-parse --show-toplevel) || die "not in a git checkout"
  rm -rf "$dest"; mkdir -p "$dest"
  if [ "$ref" = worktree ]; then
    (cd "$top" && git ls-files -z | tar --null -T - -cf -) | tar -xf - -C "$dest"
  else
    git -C "$top" archive --format=tar "$ref" | tar -xf - -C "$dest"
  fi
}

# json FILE KEY=VALUE ... KEY:=JSON ...: writes a JSON object; KEY=VALUE a string, KEY:=JSON a number, true,
# false or null as written (an empty JSON is null)
json() {
  local file=$1; shift
  mkdir -p "$(dirname "$file")"
  python3 - "$file" "$@" <<'EOF'
import json, sys
out = {}
for kv in sys.argv[2:]:
    k, v = kv.split("=", 1)
    out[k.rstrip(":")] = (json.loads(v) if v.strip() else None) if k.endswith(":") else v
with open(sys.argv[1], "w") as f:
    json.dump(out, f, indent=1, allow_nan=False)
    f.write("\n")
EOF
}
