#!/bin/sh
# The entry point of one pod of the relight Indexed Job (relight-job.yaml): relights the
# recording on line JOB_COMPLETION_INDEX (counting from 0) of the list, with
# `lsydrelight relight`, and exits with its status.
#
#   LSYDRELIGHT_LIST  the list: one face recording a line, optionally a tab and its
#                     screen recording; blank lines and lines starting with # are not
#                     counted; relative paths are relative to LSYDRELIGHT_CALLS
#   LSYDRELIGHT_CALLS where the recordings are (default: the list's folder)
#   LSYDRELIGHT_OUT   the folder for the relit recordings: NAME.mp4 and NAME.mkv keep
#                     their container, other recordings become NAME.mkv
#   LSYDRELIGHT       the command (default: lsydrelight on PATH)
# Arguments are passed on to `lsydrelight relight` (e.g. --target, --model).
#
# Exit status: lsydrelight's (0 relit, 1 bad input or a failed run, 2 usage error, 130
# stopped), and 2 when this pod's index or the list is wrong. The Job's podFailurePolicy
# fails the index without a retry on 1 and 2; anything else (the pod killed, the node
# gone) is retried up to backoffLimitPerIndex times.
set -eu

fail() {
    echo "error: $*" >&2
    exit 2
}

index=${JOB_COMPLETION_INDEX:-}
case $index in
    '' | *[!0-9]*) fail "JOB_COMPLETION_INDEX is '${index}'; run this as a pod of an Indexed Job" ;;
esac
list=${LSYDRELIGHT_LIST:?LSYDRELIGHT_LIST names the list of recordings}
out_dir=${LSYDRELIGHT_OUT:?LSYDRELIGHT_OUT names the folder for the relit recordings}
[ -f "$list" ] || fail "the list $list does not exist; mount it (see relight-job.yaml)"
calls=${LSYDRELIGHT_CALLS:-$(dirname "$list")}

tab=$(printf '\t')
entry=$(grep -v -e '^[[:space:]]*$' -e '^[[:space:]]*#' "$list" | sed -n "$((index + 1))p")
[ -n "$entry" ] || fail "the list $list has no entry $index (it has $(grep -c -v -e '^[[:space:]]*$' -e '^[[:space:]]*#' "$list")); set the Job's completions to the number of entries"
face=${entry%%"$tab"*}
screen=
[ "$face" = "$entry" ] || screen=${entry#*"$tab"}

absolute() {
    case $1 in
        /*) printf '%s' "$1" ;;
        *) printf '%s/%s' "$calls" "$1" ;;
    esac
}
face=$(absolute "$face")
name=$(basename "$face")
stem=${name%.*}
case $name in
    *.mp4 | *.MP4) out=$out_dir/$stem.mp4 ;;
    *.mkv | *.MKV) out=$out_dir/$stem.mkv ;;
    *) out=$out_dir/$stem.mkv ;;
esac
mkdir -p "$out_dir"

echo "index $index: $face -> $out" >&2
if [ -n "$screen" ]; then
    exec "${LSYDRELIGHT:-lsydrelight}" relight --face "$face" --screen "$(absolute "$screen")" --out "$out" "$@"
fi
exec "${LSYDRELIGHT:-lsydrelight}" relight --face "$face" --out "$out" "$@"
