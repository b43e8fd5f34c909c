#!/usr/bin/env bash
# Fetch PVM volumes of Stefan Roettger's V^3 "Volume Library" (Bucky, Lobster, Foot, ...).
# volao reads .pvm directly, DDS-compressed ones included.
#
# UNTESTED against the real servers: it was written on a machine without internet access.
# The original host was reported unreachable in January 2024 (see README.md), so the
# script tries, per file: a mirror you name (--base / $VOLAO_V3_BASE_URL), the original
# URL, the Internet Archive's copy of it, and for Bucky and Lobster a copy committed to
# the Radium-Engine repository on GitHub (pinned commits).
set -euo pipefail

PROG=$(basename -- "$0")
ORIGINAL_BASE="http://schorsch.efi.fh-nuernberg.de/data/volume"
# "id_" asks the Wayback Machine for the archived bytes unmodified; a partial timestamp
# redirects to the nearest capture. Whether a given file was captured is not verified.
ARCHIVE_PREFIX="https://web.archive.org/web/2019id_/"
RADIUM_RAW="https://raw.githubusercontent.com/STORM-IRIT/Radium-Engine"

DEFAULT_NAMES=(Bucky Lobster Foot)

# NAME | what the evidence says (dims from pvm2raw output or code comments quoted in
# public code; every file name below appears in public code that loads a .pvm
# downloaded from the library, only Foot.pvm's full URL is quoted verbatim).
KNOWN=(
    "Bucky|32x32x32, 8 bit; courtesy AVS; also shipped inside the V^3 source package"
    "Lobster|301x324x56, 8 bit, spacing 1:1:1.4; courtesy VolVis (SUNY Stony Brook)"
    "Foot|256x256x256, 8 bit; full URL quoted verbatim in public docs"
    "VisMale|128x256x256, 8 bit"
    "Bonsai1-LO|512x512x182, 16 bit (large: ~95 MB uncompressed)"
    "Bonsai3-LO|name seen in public code; size not known here"
    "Engine|name seen in public code; size not known here"
    "Box|name seen in public code; size not known here"
    "Carp|name seen in public code; size not known here"
    "Clouds|name seen in public code; size not known here"
    "CTA-Brain|name seen in public code; size not known here"
    "CT-Chest|name seen in public code; size not known here"
    "Daisy|name seen in public code; size not known here"
    "DTI-B0|name seen in public code; size not known here"
    "Sheep|name seen in public code; size not known here"
    "Tooth|name seen in public code; size not known here"
    "XMasTree-LO|name seen in public code; size not known here"
    "Pig|name seen in public code; size not known here"
    "MRI-Head|name seen in public code; size not known here"
    "Baby|name seen in public code; size not known here"
    "Orange|name seen in public code; size not known here"
    "Porsche|name seen in public code; size not known here"
)

usage() {
    cat <<EOF
Usage: $PROG [options] [NAME ...]

Downloads PVM volumes from the V^3 Volume Library (Stefan Roettger) into
OUT/v3/NAME.pvm, where OUT is --out DIR, else \$VOLAO_DATA_OUT, else ./data.
NAME is a data set name such as Bucky or Lobster (case-insensitive, ".pvm"
optional). Without NAMEs it fetches: ${DEFAULT_NAMES[*]}.

Options:
  --out DIR      output root (files go to DIR/v3/)
  --all          fetch every name in --list
  --list         list the known names and exit
  --base URL     try this mirror first: URL/NAME.pvm (also \$VOLAO_V3_BASE_URL)
  --no-archive   do not try the Internet Archive (web.archive.org) copy
  --force        download again even if OUT/v3/NAME.pvm exists
  -h, --help     show this help

For each file it tries, in order, until one answers with a PVM file:
  1. --base / \$VOLAO_V3_BASE_URL, if given
  2. $ORIGINAL_BASE/NAME.pvm   (the original host)
  3. ${ARCHIVE_PREFIX}$ORIGINAL_BASE/NAME.pvm
  4. Bucky and Lobster only: the copies committed to $RADIUM_RAW
A download counts only if it starts like a PVM file (PVM, PVM2, PVM3, or
DDS v3d / DDS v3e for the compressed ones); anything else, such as an HTML error
page, is discarded. Files already present are kept. Needs curl or wget.

Terms: "Commercial use is prohibited and no warranty whatsoever is expressed"
(the library's terms as quoted by Radium-Engine); each data set also has its own
courtesy line. See README.md beside this script.
NOTE: untested here (no network where it was written); see README.md.
EOF
}

die() { echo "$PROG: error: $*" >&2; exit 1; }
say() { echo "$PROG: $*"; }

OUT=""
BASE=${VOLAO_V3_BASE_URL:-}
ALL=0
FORCE=0
ARCHIVE=1
NAMES=()
while [[ $# -gt 0 ]]; do
    case "$1" in
        -h|--help) usage; exit 0 ;;
        --list)
            printf '%-12s %s\n' NAME "NOTES (from public code; see README.md)"
            for entry in "${KNOWN[@]}"; do
                printf '%-12s %s\n' "${entry%%|*}" "${entry#*|}"
            done
            exit 0 ;;
        --all) ALL=1 ;;
        --force) FORCE=1 ;;
        --no-archive) ARCHIVE=0 ;;
        --out) [[ $# -ge 2 ]] || die "--out needs a folder"; OUT=$2; shift ;;
        --out=*) OUT=${1#--out=} ;;
        --base) [[ $# -ge 2 ]] || die "--base needs a URL"; BASE=$2; shift ;;
        --base=*) BASE=${1#--base=} ;;
        --) shift; NAMES+=("$@"); break ;;
        -*) die "unknown option '$1' (see --help)" ;;
        *) NAMES+=("$1") ;;
    esac
    shift
done
OUT=${OUT:-${VOLAO_DATA_OUT:-./data}}
BASE=${BASE%/}

if [[ $ALL -eq 1 ]]; then
    NAMES=()
    for entry in "${KNOWN[@]}"; do NAMES+=("${entry%%|*}"); done
elif [[ ${#NAMES[@]} -eq 0 ]]; then
    NAMES=("${DEFAULT_NAMES[@]}")
fi

if command -v curl >/dev/null 2>&1; then
    FETCHER=curl
elif command -v wget >/dev/null 2>&1; then
    FETCHER=wget
else
    die "neither curl nor wget is installed"
fi

# canonical NAME (known spelling) for a user-given name; unknown names pass through
canonical() {
    local want=${1%.pvm} entry name lower
    want=${want%.PVM}
    lower=$(printf '%s' "$want" | tr '[:upper:]' '[:lower:]')
    for entry in "${KNOWN[@]}"; do
        name=${entry%%|*}
        if [[ "$(printf '%s' "$name" | tr '[:upper:]' '[:lower:]')" == "$lower" ]]; then
            echo "$name"
            return 0
        fi
    done
    echo "$want"
    return 1
}

# URLs to try for NAME, one per line
sources() {
    local name=$1 file="$1.pvm"
    [[ -n "$BASE" ]] && echo "$BASE/$file"
    echo "$ORIGINAL_BASE/$file"
    [[ $ARCHIVE -eq 1 ]] && echo "$ARCHIVE_PREFIX$ORIGINAL_BASE/$file"
    case "$name" in
        Bucky)
            echo "$RADIUM_RAW/8403893a41117666242bd4d37fc44621ab006fb4/tests/unittest/data/Bucky.pvm" ;;
        Lobster)
            echo "$RADIUM_RAW/517c15f9daf06ac4f3c21dfa4187ea8fd9c5d95d/tests/unittest/data/Lobster.pvm"
            echo "$RADIUM_RAW/abaa3c813affe03ffa17ed271a3bc148bc0703fd/examples/Volume/Assets/Lobster.pvm" ;;
    esac
    return 0
}

# fetch URL into FILE; returns non-zero (and says why on stderr) on failure
fetch() {
    local url=$1 file=$2
    case "$FETCHER" in
        curl) curl -fsSL --retry 2 --connect-timeout 20 --max-time 3600 -o "$file" -- "$url" ;;
        wget) wget -q --tries=2 --timeout=20 -O "$file" -- "$url" ;;
    esac
}

# is FILE a PVM (plain or DDS-compressed)?
is_pvm() {
    local head
    head=$(head -c 8 -- "$1" 2>/dev/null | tr -d '\0' || true)
    case "$head" in
        "DDS v3d"*|"DDS v3e"*|PVM$'\n'*|PVM2$'\n'*|PVM3$'\n'*) return 0 ;;
    esac
    return 1
}

if [[ ! -d "$OUT" ]]; then
    mkdir -p -- "$OUT"
    # a folder this script creates keeps itself out of any git work tree it lands in
    printf '# downloaded data: never commit\n*\n' > "$OUT/.gitignore"
fi
mkdir -p -- "$OUT/v3"
DEST=$(cd -- "$OUT/v3" && pwd)
failed=()
for raw_name in "${NAMES[@]}"; do
    if ! name=$(canonical "$raw_name"); then
        say "note: '$raw_name' is not in --list; trying $name.pvm anyway (file names are case-sensitive on the server)"
    fi
    target="$DEST/$name.pvm"
    if [[ $FORCE -eq 0 && -f "$target" ]] && is_pvm "$target"; then
        say "keep  $target (already there)"
        continue
    fi
    part="$target.part"
    ok=0
    tried=()
    while IFS= read -r url; do
        [[ -n "$url" ]] || continue
        tried+=("$url")
        say "get   $name.pvm <- $url"
        rm -f -- "$part"
        if ! fetch "$url" "$part"; then
            say "      failed ($FETCHER could not fetch it)"
            continue
        fi
        if ! is_pvm "$part"; then
            say "      failed: the reply is not a PVM file (starts with: $(head -c 40 -- "$part" | tr -c '[:print:]' '.'))"
            continue
        fi
        mv -f -- "$part" "$target"
        say "wrote $target ($(wc -c < "$target" | tr -d ' ') bytes)"
        ok=1
        break
    done < <(sources "$name")
    rm -f -- "$part"
    if [[ $ok -eq 0 ]]; then
        {
            echo "$PROG: error: could not fetch $name.pvm; tried:"
            printf '    %s\n' "${tried[@]}"
        } >&2
        failed+=("$name")
    fi
done

if [[ ${#failed[@]} -gt 0 ]]; then
    cat >&2 <<EOF
$PROG: ${#failed[@]} file(s) failed: ${failed[*]}
  The original host has been reported offline; if you know a working mirror of the
  Volume Library, pass it with --base URL (files are fetched as URL/NAME.pvm).
EOF
    exit 1
fi
say "done; volumes are in $DEST (try: volao info $DEST/${NAMES[0]}.pvm)"
