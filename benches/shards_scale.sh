#!/usr/bin/env bash
# Per-round time, per-shard peak memory and bytes written of sharded bakes
# run locally (scripts/shards-local.sh), for docs/scale.md's table.
#
#   benches/shards_scale.sh MESH "N…" [bake args…]      (from the repository root)
#   e.g. JOBS=2 benches/shards_scale.sh ferrari.glb "1 2 4 8" --window Glass_Gray --rays 64 --bounces 3
#
# Every prtbake process runs under /usr/bin/time (GNU time, max RSS); prints a
# Markdown row per N and round: shards' wall time (first start to last end),
# the merge's, the largest shard RSS, the merge's RSS, and the bytes the
# round wrote (parts, hit records, the merged layer or bundle). Environment:
# JOBS (shards at once, default 2), SCRATCH (default /tmp/prtbake-shards-scale,
# wiped per N), PRTBAKE (default target/release/prtbake).
set -euo pipefail
[ $# -ge 2 ] || { echo "usage: $0 MESH \"N…\" [bake args…]" >&2 && exit 2; }
mesh=$(realpath "$1") counts=$2
shift 2
[ -x /usr/bin/time ] || { echo "$0: needs GNU time at /usr/bin/time (apt-get install time)" >&2 && exit 2; }
real=$(realpath "${PRTBAKE:-target/release/prtbake}")
scratch=${SCRATCH:-/tmp/prtbake-shards-scale}
export JOBS=${JOBS:-2}

# A prtbake that logs "command round start end max_rss_kib output_bytes" per run.
mkdir -p "$scratch"
wrapper=$scratch/prtbake-timed
cat >"$wrapper" <<WRAP
#!/usr/bin/env bash
round=- out= prev=
for a; do case \$prev in --round) round=\$a ;; -o) out=\$a ;; esac; prev=\$a; done
start=\$(date +%s.%N)
/usr/bin/time -f %M -o "\$out.rss" "$real" "\$@"
echo "\$1 \$round \$start \$(date +%s.%N) \$(cat "\$out.rss") \$(stat -c %s "\$out")" >>"$scratch/log"
rm -f "\$out.rss"
WRAP
chmod +x "$wrapper"

echo "| N | round | shards s | merge s | shard peak RSS MiB | merge RSS MiB | bytes written |"
echo "|---:|---:|---:|---:|---:|---:|---:|"
for n in $counts; do
    rm -rf "$scratch/n$n" "$scratch/log" && mkdir -p "$scratch/n$n"
    PRTBAKE=$wrapper WORK=$scratch/n$n/work scripts/shards-local.sh "$mesh" "$scratch/n$n/out.prtb" "$n" "$@" 2>/dev/null
    hits=$(du -cb "$scratch/n$n/work/hits" | tail -n 1 | cut -f1)
    # Shards log their round; a merge closes the round of the shards before it.
    awk -v n="$n" -v hits="$hits" '
        $1 == "bake" { r = $2; if (!(r in s0) || $3 < s0[r]) s0[r] = $3; if ($4 > s1[r]) s1[r] = $4
                       if ($5 > rss[r]) rss[r] = $5; bytes[r] += $6 }
        $1 == "merge" { mt[r] = $4 - $3; mrss[r] = $5; bytes[r] += $6 }
        END { for (i = 0; i <= r; i++)
                  printf "| %d | %d | %.1f | %.1f | %d | %d | %.1f MB |\n", n, i, s1[i] - s0[i], mt[i], rss[i] / 1024, mrss[i] / 1024,
                         (bytes[i] + (i == 0 ? hits : 0)) / 1e6 }' "$scratch/log"
done
