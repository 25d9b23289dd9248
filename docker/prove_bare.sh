#!/usr/bin/env bash
# Proves the README's first command on a bare Debian 12, and writes what it measured to docs/figures/image/bare.json.
# tests/run.sh --bare runs it (not in CI). As root; needs no container engine.
#
#   1. debootstrap --variant=minbase BARE_SUITE (docker/rootfs.sh: Debian 12 by default; the suite, mirror and
#      components are variables, docs/install.md has Ubuntu 24.04's), into $FLEXSHEET_IMAGE_WORK/bare-SUITE.
#   2. The checkout's tracked files of BARE_SOURCE (HEAD: git archive; "worktree": as they are now), never .venv,
#      copied to /opt/flexsheet there (where the README's clone puts them); the host's resolv.conf, local CAs and
#      pip configuration copied in, so that pip reaches the index as it does here.
#   3. In it, with chroot in its own mount namespace (every mount undone after, also on failure):
#      cd /opt/flexsheet && bash docker/install.sh, then flexsheet launch launch/sim.yaml --out out/sim
#      (the README's `bash docker/install.sh && flexsheet launch launch/sim.yaml --out out/sim`, timed apart);
#      then, as a new user, flexsheet --help (the link in /usr/local/bin reaches every user).
#   4. The root is removed after (BARE_KEEP=1 keeps it), only once nothing is mounted in it.
# Exits 0 when the install, the main job and the other user's run exited 0; else 1. bare.json is written either way.
#
#   docker/prove_bare.sh                       # or tests/run.sh --bare
#   BARE_JSON=/tmp/bare.json BARE_SOURCE=worktree BARE_KEEP=1 docker/prove_bare.sh
set -uo pipefail
cd "$(dirname "$0")/.." || exit 1
PROG=bare
# shellcheck source=rootfs.sh
. docker/rootfs.sh
OUT_JSON=${BARE_JSON:-docs/figures/image/bare.json}
SOURCE=${BARE_SOURCE:-HEAD}
CODE=/opt/flexsheet
ROOT="$WORK/bare-$BARE_SUITE"
[ "$(id -u)" -eq 0 ] || die "run as root (debootstrap, chroot, mounts)"
need debootstrap debootstrap unshare util-linux
mkdir -p "$WORK"
commit=$(git rev-parse --short "${SOURCE/worktree/HEAD}") || die "BARE_SOURCE $SOURCE is not a commit"
[ "$SOURCE" = worktree ] && commit="$commit+worktree"
# shellcheck disable=SC2317  # run by the EXIT trap
cleanup() {
  if [ "${BARE_KEEP:-0}" = 1 ]; then log "BARE_KEEP=1: $ROOT kept"; else remove_root "$ROOT"; fi
}
trap cleanup EXIT

t0=$(date +%s)
make_rootfs "$ROOT"
debootstrap_s=$(($(date +%s) - t0))
mirror_host_config "$ROOT"
export_source "$ROOT$CODE" "$SOURCE"
log "$BARE_SUITE in $ROOT after $debootstrap_s s; $commit's tracked files in $CODE"

log "bash docker/install.sh (log $WORK/bare-install.log)"
load0=$(cut -d' ' -f1-3 /proc/loadavg)   # the machine's load as the install starts
t0=$(date +%s)
in_root "$ROOT" "cd $CODE && bash docker/install.sh" >"$WORK/bare-install.log" 2>&1
install_rc=$?
install_s=$(($(date +%s) - t0))
tail -n 5 "$WORK/bare-install.log"
main_rc=null main_s=null rtf=null user_rc=null load=null
if [ $install_rc -eq 0 ]; then
  log "installed in $install_s s; flexsheet launch launch/sim.yaml --out out/sim (log $WORK/bare-main.log)"
  load=$(cut -d' ' -f1-3 /proc/loadavg)   # the machine's load as the main job starts
  t0=$(date +%s)
  in_root "$ROOT" "cd $CODE && flexsheet launch launch/sim.yaml --out out/sim" >"$WORK/bare-main.log" 2>&1
  main_rc=$?
  main_s=$(($(date +%s) - t0))
  tail -n 5 "$WORK/bare-main.log"
  rtf=$(python3 -c 'import json, sys; print(round(json.load(open(sys.argv[1]))["realtime_factor"], 3))' \
        "$ROOT$CODE/out/sim/sim_clock.json" 2>/dev/null || echo null)
  log "as a new user (no access to root's home): flexsheet --help"
  in_root "$ROOT" "useradd --create-home fsuser && cd /home/fsuser && runuser -u fsuser -- flexsheet --help" \
    >"$WORK/bare-user.log" 2>&1
  user_rc=$?
else
  log "the install failed (exit $install_rc): the main job not run"
fi
left=$(mounts_under "$ROOT")
python_v=$(chroot "$ROOT" /usr/bin/python3 --version 2>/dev/null)
json "$OUT_JSON" suite="$BARE_SUITE" mirror="$BARE_MIRROR" variant=minbase debootstrap_s:=$debootstrap_s \
  install_rc:=$install_rc install_s:=$install_s loadavg_at_install="$load0" \
  main_job_rc:=$main_rc main_job_s:=$main_s loadavg_at_main_job="$load" realtime_factor:="$rtf" \
  other_user_help_rc:=$user_rc mounts_left:="$left" python="$python_v" commit="$commit" cores:="$(nproc)" \
  command="cd $CODE && bash docker/install.sh && flexsheet launch launch/sim.yaml --out out/sim" \
  date="$(date -u +%FT%TZ)" \
  note="chroot in a private mount namespace; the host's resolv.conf, local CAs and pip configuration copied in (this network's PyPI goes through a TLS proxy); install_s with a cold pip cache; realtime_factor: out/sim/sim_clock.json (simulated s per wall s); other_user_help_rc: flexsheet --help as a new user through /usr/local/bin"
log "wrote $OUT_JSON"
[ "$left" -eq 0 ] || log "FAILED: $left mounts left under $ROOT"
if [ $install_rc -eq 0 ] && [ "$main_rc" -eq 0 ] && [ "$user_rc" -eq 0 ] && [ "$left" -eq 0 ]; then
  log "install $install_s s, main job $main_s s (real-time factor $rtf): passed"
  exit 0
fi
log "FAILED: install exit $install_rc, main job exit $main_rc, other user exit $user_rc"
exit 1
