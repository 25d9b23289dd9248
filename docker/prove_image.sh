#!/usr/bin/env bash
# Builds the shipped image (docker/Dockerfile) without a Docker engine, runs the README's main job inside it, and
# writes what it measured to docs/figures/image/image.json. tests/run.sh --image runs it (not in CI). As root.
#
#   1. buildah (Debian's package: daemonless; vfs storage and chroot isolation, so no engine, no user namespaces);
#      its storage lies in $FLEXSHEET_IMAGE_WORK (/var/tmp/flexsheet-image), outside the checkout.
#   2. The Dockerfile's FROM image: used if already in that storage, else pulled, else (no registry reachable) made
#      from Debian's archive: debootstrap BARE_SUITE + python3 + ca-certificates, packed as a tar and imported
#      (FROM scratch, ADD base.tar /), tagged with the FROM name. Its Python is Debian's /usr/bin/python3 (the
#      official image's is /usr/local/bin/python3); docker/install.sh adds python3-venv and python3-dev for it.
#   3. buildah bud --layers of the Dockerfile, from the tracked files of IMAGE_SOURCE (HEAD: git archive, or
#      "worktree"); the host's pip configuration (and the CA it names) is mounted for the build's RUN steps only.
#   4. The build stage alone as an image (--target build: its layers are cached, seconds): what a single-stage
#      image (compiler, headers, sources and all) would weigh.
#   5. In the runtime image, as its own user (uid 1000): no gcc, no Node.js, gi.repository.Aravis imports, and
#      flexsheet launch launch/sim.yaml --out out/sim (the image holds launch/ and README.md only) exits 0.
# Exits 0 when every check passed; 1 when one failed (image.json is written all the same, with the real values).
#
#   docker/prove_image.sh                      # or tests/run.sh --image
#   IMAGE_FRESH=1 docker/prove_image.sh        # remove the base and the cached layers first (a cold build)
#   IMAGE_JSON=/tmp/image.json IMAGE_SOURCE=worktree docker/prove_image.sh
set -uo pipefail
cd "$(dirname "$0")/.." || exit 1
PROG=image
# shellcheck source=rootfs.sh
. docker/rootfs.sh
OUT_JSON=${IMAGE_JSON:-docs/figures/image/image.json}
SOURCE=${IMAGE_SOURCE:-HEAD}
TAG=${FLEXSHEET_IMAGE_TAG:-flexsheet}
[ "$(id -u)" -eq 0 ] || die "run as root (debootstrap, chroot, buildah's vfs storage)"
need buildah buildah debootstrap debootstrap
mkdir -p "$WORK"
B=(buildah --storage-driver vfs --root "$WORK/storage" --runroot "$WORK/run")
FROM=$(awk 'toupper($1) == "FROM" {print $2; exit}' docker/Dockerfile)
[ -n "$FROM" ] || die "no FROM in docker/Dockerfile"
commit=$(git rev-parse --short "${SOURCE/worktree/HEAD}") || die "IMAGE_SOURCE $SOURCE is not a commit"
[ "$SOURCE" = worktree ] && commit="$commit+worktree"

if [ "${IMAGE_FRESH:-0}" = 1 ]; then
  log "IMAGE_FRESH=1: removing the images and cached layers of $WORK/storage"
  "${B[@]}" rm --all >/dev/null 2>&1
  "${B[@]}" rmi --all --force >/dev/null 2>&1
fi

# --- 2. the FROM image ---------------------------------------------------------------------------------------
t0=$(date +%s)
if "${B[@]}" inspect --type image "$FROM" >/dev/null 2>&1; then
  base_source=cached
  log "base $FROM: already in $WORK/storage"
elif timeout 120 "${B[@]}" pull --quiet "docker.io/library/$FROM" >"$WORK/pull.log" 2>&1; then
  base_source=pulled
  log "base $FROM: pulled"
else
  base_source=debootstrap
  log "base $FROM cannot be pulled ($(tail -n 1 "$WORK/pull.log")): making it from $BARE_MIRROR"
  need tar tar
  make_rootfs "$WORK/base-root" python3,ca-certificates
  rm -rf "$WORK/base-root/var/cache/apt/archives/"*.deb "$WORK/base-root/var/lib/apt/lists/"* \
         "$WORK/base-root/dev/"* "$WORK/base-root/proc/"* "$WORK/base-root/sys/"*
  mkdir -p "$WORK/base"
  tar --numeric-owner -C "$WORK/base-root" -cf "$WORK/base/base.tar" . || die "packing the base failed"
  remove_root "$WORK/base-root"
  cat >"$WORK/base/Containerfile" <<'EOF'
FROM scratch
ADD base.tar /
ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin LANG=C.UTF-8
CMD ["python3"]
EOF
  "${B[@]}" bud --isolation chroot --pull-never -f "$WORK/base/Containerfile" -t "$FROM" "$WORK/base" \
    >"$WORK/base.log" 2>&1 || { tail -n 20 "$WORK/base.log" >&2; die "importing the base failed ($WORK/base.log)"; }
  rm -f "$WORK/base/base.tar"
fi
base_s=$(($(date +%s) - t0))

# --- 3. the image --------------------------------------------------------------------------------------------
ctx="$WORK/context"
export_source "$ctx" "$SOURCE"
mounts=()
while IFS= read -r f; do
  case "$f" in "$HOME"/*) mounts+=(-v "$f:/root/${f#"$HOME"/}:ro");; *) mounts+=(-v "$f:$f:ro");; esac
done < <(pip_config_files)
while IFS= read -r f; do mounts+=(-v "$f:$f:ro"); done < <(pip_config_paths)
log "buildah bud -f docker/Dockerfile -t $TAG (source $commit; log $WORK/build.log)"
t0=$(date +%s)
"${B[@]}" bud --isolation chroot --pull-never --layers "${mounts[@]}" -f docker/Dockerfile -t "$TAG" "$ctx" \
  >"$WORK/build.log" 2>&1
build_rc=$?
build_s=$(($(date +%s) - t0))
cached_steps=$(grep -c '^--> Using cache' "$WORK/build.log")
if [ $build_rc -ne 0 ]; then
  tail -n 30 "$WORK/build.log" >&2
  json "$OUT_JSON" build_rc:=$build_rc build_s:=$build_s base_source=$base_source base_s:=$base_s commit="$commit" \
    date="$(date -u +%FT%TZ)"
  die "the build failed (exit $build_rc, $build_s s; log $WORK/build.log); $OUT_JSON has what was measured"
fi
log "built in $build_s s"

# an image's size in MB (10^6 bytes): the apparent size of its file tree, mounted (du -sb), as a container
# engine's uncompressed size counts it
size_mb() {
  local c m n
  c=$("${B[@]}" from --pull-never "$1") || return 1
  m=$("${B[@]}" mount "$c") && n=$(du -sb "$m" | cut -f1)
  "${B[@]}" umount "$c" >/dev/null; "${B[@]}" rm "$c" >/dev/null
  [ -n "${n:-}" ] && echo $((n / 1000000))
}
size=$(size_mb "$TAG") || die "cannot measure the size of $TAG"

# --- 4. the build stage as a single-stage image --------------------------------------------------------------
single=null
if "${B[@]}" bud --isolation chroot --pull-never --layers "${mounts[@]}" --target build -f docker/Dockerfile \
     -t "$TAG-build-stage" "$ctx" >"$WORK/build-stage.log" 2>&1; then
  single=$(size_mb "$TAG-build-stage")
else
  log "the build stage alone did not build ($WORK/build-stage.log): single_stage_size_mb null"
fi
log "size $size MB (the build stage alone: $single MB)"

# --- 5. checks in the runtime image --------------------------------------------------------------------------
ctr=$("${B[@]}" from --pull-never "$TAG") || die "buildah from $TAG failed"
trap '"${B[@]}" rm "$ctr" >/dev/null 2>&1' EXIT
in_image() { "${B[@]}" run --isolation chroot --user 1000:1000 "$ctr" -- "$@"; }
user_uid=$(in_image id -u) || die "id -u in the image failed"
# the compilers and Node.js on the user's PATH (and in /usr/bin), one a line; nothing when none
# shellcheck disable=SC2016  # expanded by the image's sh
found=$(in_image sh -c 'for c in gcc cc c++ x86_64-linux-gnu-gcc-12 node nodejs npm; do
  command -v "$c" || ls "/usr/bin/$c" 2>/dev/null; done; exit 0') || die "buildah run in $TAG failed"
has_gcc=false; grep -qE '/(gcc|cc|c\+\+|x86_64-linux-gnu-gcc-12)$' <<<"$found" && has_gcc=true
has_node=false; grep -qE '/(node|nodejs|npm)$' <<<"$found" && has_node=true
[ -z "$found" ] || log "found in the image: $(echo "$found" | sort -u | tr '\n' ' ')"
aravis_import=false
in_image python -c "import gi; gi.require_version('Aravis', '0.8'); from gi.repository import Aravis; \
print('gi.repository.Aravis imports:', Aravis.__name__)" >"$WORK/aravis.log" 2>&1 && aravis_import=true
cat "$WORK/aravis.log"
log "uid $user_uid, gcc $has_gcc, node $has_node, Aravis import $aravis_import; the main job (log $WORK/main.log)"
load=$(cut -d' ' -f1-3 /proc/loadavg)   # the machine's load as the main job starts
t0=$(date +%s)
in_image sh -c 'ls -A; flexsheet launch launch/sim.yaml --out out/sim' >"$WORK/main.log" 2>&1
main_rc=$?
main_s=$(($(date +%s) - t0))
tail -n 15 "$WORK/main.log"
# the run's real-time factor (simulated s per wall s), from the run's sim_clock.json
rtf=$(in_image cat out/sim/sim_clock.json 2>/dev/null \
      | python3 -c 'import json, sys; print(round(json.load(sys.stdin)["realtime_factor"], 3))' 2>/dev/null)

json "$OUT_JSON" size_mb:="$size" single_stage_size_mb:="$single" build_s:=$build_s cached_steps:="$cached_steps" \
  base_s:=$base_s \
  base_source=$base_source base="$FROM from $BARE_SUITE ($BARE_MIRROR), Debian's python3" \
  user_uid:="$user_uid" has_gcc:=$has_gcc has_node:=$has_node aravis_import:=$aravis_import \
  main_job_rc:=$main_rc main_job_s:=$main_s loadavg_at_main_job="$load" realtime_factor:="${rtf:-null}" \
  main_job="flexsheet launch launch/sim.yaml --out out/sim (uid 1000, in /opt/flexsheet: launch/, README.md)" \
  builder="$(buildah --version) --storage-driver vfs --isolation chroot --layers" commit="$commit" \
  cores:="$(nproc)" date="$(date -u +%FT%TZ)" \
  note="size_mb: the runtime image's file tree, mounted, du -sb (uncompressed, 10^6 bytes); single_stage_size_mb: the build stage built alone (--target build), what one stage shipping compiler, headers and sources would weigh; build_s: the Dockerfile's build (cold when cached_steps is 0); base_s: making the FROM image"
log "wrote $OUT_JSON"
ok=1
[ "$main_rc" -eq 0 ] || { log "FAILED: the main job exited $main_rc ($WORK/main.log)"; ok=0; }
[ "$user_uid" -ge 1 ] || { log "FAILED: runs as uid $user_uid"; ok=0; }
[ $has_gcc = false ] || { log "FAILED: the runtime image has a compiler"; ok=0; }
[ $has_node = false ] || { log "FAILED: the runtime image has Node.js"; ok=0; }
[ $aravis_import = true ] || { log "FAILED: gi.repository.Aravis does not import ($WORK/aravis.log)"; ok=0; }
[ $ok -eq 1 ] && log "every check passed" && exit 0
exit 1
