#!/usr/bin/env bash
# Fetch real MRI / CT volumes that Debian ships as packages, without installing them:
#   mricron-data        -> MRIcron's NIfTI templates (ch2.nii.gz, ch2better.nii.gz, ...)
#   invesalius-examples -> InVesalius' example CT project Cranium.inv3, converted to
#                          Cranium.raw + Cranium.dat (256x256x108 int16, Inviwo sidecar)
# `apt-get download` needs no root; it needs apt's package lists (see --help).
set -euo pipefail

SCRIPT_DIR=$(cd -- "$(dirname -- "${BASH_SOURCE[0]}")" && pwd)
PROG=$(basename -- "$0")

usage() {
    cat <<EOF
Usage: $PROG [options] [OUT_DIR]      (or --out OUT_DIR)

Downloads the Debian packages mricron-data and invesalius-examples with
'apt-get download' (no root needed), unpacks them with 'dpkg-deb -x' into a
temporary folder and copies the volumes out:

  OUT_DIR/mricron/*.nii.gz       MRIcron templates: ch2.nii.gz, ch2bet.nii.gz,
                                 ch2better.nii.gz, aal.nii.gz, ... (~16 MB .deb)
  OUT_DIR/invesalius/Cranium.raw  CT head, 256x256x108 int16 (13.5 MiB), and
  OUT_DIR/invesalius/Cranium.dat  its Inviwo sidecar (spacing 0.957 0.957 1.5 mm),
                                 extracted from Cranium.inv3 (~19 MB .deb)

OUT_DIR defaults to \$VOLAO_DATA_OUT, else ./data. Files already there are kept,
so running it again downloads nothing (unless --force).

Options:
  --out DIR      output folder (same as the OUT_DIR argument)
  --only PKG     only mricron | invesalius (may be repeated)
  --keep-inv3    also keep the original Cranium.inv3 project in OUT_DIR/invesalius/
  --keep-debs    keep the downloaded .deb files in OUT_DIR/debs/
  --force        re-download and overwrite
  -h, --help     show this help

Requirements: apt-get and dpkg-deb (Debian/Ubuntu), python3 (standard library
only, for the .inv3 conversion by inv3-to-raw.py beside this script).
If apt-get says it cannot locate a package, its package lists are missing or
stale: run 'sudo apt-get update' once (that step does need root). Both packages
are in Debian main (bookworm: mricron-data 1.2.20211006+dfsg-4,
invesalius-examples 3.1.99998-4); on Ubuntu they are in universe.
EOF
}

die() { echo "$PROG: error: $*" >&2; exit 1; }
say() { echo "$PROG: $*"; }

OUT=""
FORCE=0
KEEP_INV3=0
KEEP_DEBS=0
WANT_MRICRON=0
WANT_INVESALIUS=0
ONLY_GIVEN=0
while [[ $# -gt 0 ]]; do
    case "$1" in
        -h|--help) usage; exit 0 ;;
        --force) FORCE=1 ;;
        --keep-inv3) KEEP_INV3=1 ;;
        --keep-debs) KEEP_DEBS=1 ;;
        --out) [[ $# -ge 2 ]] || die "--out needs a folder"; OUT=$2; shift ;;
        --out=*) OUT=${1#--out=} ;;
        --only)
            [[ $# -ge 2 ]] || die "--only needs mricron or invesalius"
            ONLY_GIVEN=1
            case "$2" in
                mricron|mricron-data) WANT_MRICRON=1 ;;
                invesalius|invesalius-examples) WANT_INVESALIUS=1 ;;
                *) die "--only: unknown package '$2' (mricron or invesalius)" ;;
            esac
            shift ;;
        --) shift; break ;;
        -*) die "unknown option '$1' (see --help)" ;;
        *) [[ -z "$OUT" ]] || die "only one OUT_DIR may be given"; OUT="$1" ;;
    esac
    shift
done
if [[ $# -gt 0 ]]; then
    [[ -z "$OUT" && $# -eq 1 ]] || die "only one OUT_DIR may be given"
    OUT="$1"
fi
if [[ $ONLY_GIVEN -eq 0 ]]; then WANT_MRICRON=1; WANT_INVESALIUS=1; fi
OUT=${OUT:-${VOLAO_DATA_OUT:-./data}}

for tool in apt-get dpkg-deb; do
    command -v "$tool" >/dev/null 2>&1 || die "'$tool' not found: this script needs a Debian or Ubuntu system"
done

if [[ ! -d "$OUT" ]]; then
    mkdir -p -- "$OUT"
    # a folder this script creates keeps itself out of any git work tree it lands in
    printf '# downloaded data: never commit\n*\n' > "$OUT/.gitignore"
fi
OUT=$(cd -- "$OUT" && pwd)
WORK=$(mktemp -d "${TMPDIR:-/tmp}/volao-debian.XXXXXX")
cleanup() { rm -rf -- "$WORK"; }
trap cleanup EXIT

APT_OPTS=()
if [[ ${EUID:-$(id -u)} -eq 0 ]]; then
    # As root apt hands downloads to the _apt user, who cannot write into our private
    # temp folder; it then warns and downloads as root anyway. Say so up front.
    APT_OPTS+=(-o APT::Sandbox::User=root)
fi

# download PKG -> prints the path of the .deb
download() {
    local pkg=$1 dir="$WORK/deb-$1"
    mkdir -p "$dir"
    say "downloading $pkg with apt-get download ..." >&2
    if ! (cd "$dir" && apt-get "${APT_OPTS[@]}" download "$pkg" >&2); then
        cat >&2 <<EOF
$PROG: error: 'apt-get download $pkg' failed.
  If it said "Unable to locate package", apt's package lists are missing or out of
  date: run 'sudo apt-get update' once, then run this script again (it needs no root).
  On Ubuntu, $pkg is in the 'universe' component, which must be enabled.
EOF
        return 1
    fi
    local deb
    deb=$(find "$dir" -maxdepth 1 -name "${pkg}_*.deb" | head -n 1)
    [[ -n "$deb" ]] || { echo "$PROG: error: apt-get download left no ${pkg}_*.deb" >&2; return 1; }
    if [[ $KEEP_DEBS -eq 1 ]]; then
        mkdir -p "$OUT/debs"
        cp -f -- "$deb" "$OUT/debs/"
    fi
    echo "$deb"
}

# copy SRC into DIR unless a file of that name is already there (or --force)
copy_in() {
    local src=$1 dir=$2 dst
    dst="$dir/$(basename -- "$src")"
    if [[ -e "$dst" && $FORCE -eq 0 ]]; then
        say "keep  $dst (already there)"
        return 0
    fi
    cp -f -- "$src" "$dst.part" && mv -f -- "$dst.part" "$dst"
    say "wrote $dst ($(stat -c %s -- "$dst") bytes)"
}

fetch_mricron() {
    local dest="$OUT/mricron"
    if [[ $FORCE -eq 0 && -f "$dest/ch2.nii.gz" && -f "$dest/ch2better.nii.gz" && -f "$dest/.complete" ]]; then
        say "mricron-data: already in $dest (use --force to fetch again)"
        return 0
    fi
    local deb
    deb=$(download mricron-data) || return 1
    dpkg-deb -x "$deb" "$WORK/mricron" || { echo "$PROG: error: dpkg-deb -x failed on $deb" >&2; return 1; }
    local tdir="$WORK/mricron/usr/share/mricron/templates"
    [[ -d "$tdir" ]] || { echo "$PROG: error: $deb has no usr/share/mricron/templates/ (package layout changed?)" >&2; return 1; }
    mkdir -p "$dest"
    local n=0 f
    shopt -s nullglob
    for f in "$tdir"/*.nii.gz "$tdir"/*.nii "$tdir"/*.hdr "$tdir"/*.img; do
        copy_in "$f" "$dest"
        n=$((n + 1))
    done
    shopt -u nullglob
    [[ $n -gt 0 ]] || { echo "$PROG: error: no NIfTI files found in $tdir" >&2; return 1; }
    # the package's copyright file, so the terms travel with the data
    cp -f -- "$WORK/mricron/usr/share/doc/mricron-data/copyright" "$dest/COPYRIGHT.debian" 2>/dev/null || true
    touch "$dest/.complete"
    say "mricron-data: $n volume files in $dest"
}

fetch_invesalius() {
    local dest="$OUT/invesalius"
    if [[ $FORCE -eq 0 && -f "$dest/Cranium.raw" && -f "$dest/Cranium.dat" && ( $KEEP_INV3 -eq 0 || -f "$dest/Cranium.inv3" ) ]]; then
        say "invesalius-examples: already in $dest (use --force to fetch again)"
        return 0
    fi
    command -v python3 >/dev/null 2>&1 || { echo "$PROG: error: python3 is needed to convert Cranium.inv3" >&2; return 1; }
    local deb
    deb=$(download invesalius-examples) || return 1
    dpkg-deb -x "$deb" "$WORK/invesalius" || { echo "$PROG: error: dpkg-deb -x failed on $deb" >&2; return 1; }
    local found=0 f name force_flag=()
    [[ $FORCE -eq 1 ]] && force_flag=(--force)
    mkdir -p "$dest"
    while IFS= read -r -d '' f; do
        found=1
        name=$(basename -- "$f" .inv3)
        python3 "$SCRIPT_DIR/inv3-to-raw.py" "${force_flag[@]}" "$f" "$dest" --name "$name" || return 1
        if [[ $KEEP_INV3 -eq 1 ]]; then copy_in "$f" "$dest"; fi
    done < <(find "$WORK/invesalius" -name '*.inv3' -type f -print0)
    [[ $found -eq 1 ]] || { echo "$PROG: error: no .inv3 project found in $deb" >&2; return 1; }
    cp -f -- "$WORK/invesalius/usr/share/doc/invesalius-examples/copyright" "$dest/COPYRIGHT.debian" 2>/dev/null || true
    say "invesalius-examples: done; try: volao info $dest/Cranium.raw"
}

status=0
if [[ $WANT_MRICRON -eq 1 ]]; then fetch_mricron || status=1; fi
if [[ $WANT_INVESALIUS -eq 1 ]]; then fetch_invesalius || status=1; fi
if [[ $status -ne 0 ]]; then
    echo "$PROG: some packages failed (see above)" >&2
    exit 1
fi
say "all done; volumes are under $OUT"
