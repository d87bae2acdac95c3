# Sourced by the sharded-bake launchers (shards-local.sh, slurm/submit.sh,
# kubernetes/manifests.sh): what they all read from a bake's arguments.

# Prints the bounce count the bake args "$@" ask for (the rounds are the
# bounces, 0 … B; default 0).
bounces_of() {
    local bounces=0 prev= arg
    for arg in "$@"; do
        case $prev in --bounces) bounces=$arg ;; esac
        case $arg in --bounces=*) bounces=${arg#--bounces=} ;; esac
        prev=$arg
    done
    case $bounces in '' | *[!0-9]*) echo "$0: --bounces must be a number, not '$bounces'" >&2 && return 2 ;; esac
    echo "$bounces"
}

# Succeeds when the bake args "$@" allocate adaptively: bake's default
# (--adaptive 0.25) unless --adaptive 0 or, without --adaptive, --sampling
# vertex. Such a bake has a pilot stage before round 0 (docs/scale.md).
is_adaptive() {
    local prev= arg adaptive= sampling=interior
    for arg in "$@"; do
        case $prev in --adaptive) adaptive=$arg ;; --sampling) sampling=$arg ;; esac
        case $arg in --adaptive=*) adaptive=${arg#--adaptive=} ;; --sampling=*) sampling=${arg#--sampling=} ;; esac
        prev=$arg
    done
    case $adaptive in
        '') [ "$sampling" != vertex ] ;;
        0 | 0.0 | 0.00 | .0) return 1 ;;
        *) return 0 ;;
    esac
}

# Succeeds when the bake args "$@" give --threads.
gives_threads() {
    local arg
    for arg in "$@"; do
        case $arg in --threads | --threads=*) return 0 ;; esac
    done
    return 1
}

# Checks the launchers' common operands: N a positive integer, OUT a .prtb.
check_operands() {
    local out=$1 n=$2
    case $n in '' | *[!0-9]*) echo "$0: N must be a positive integer, not '$n'" >&2 && exit 2 ;; esac
    [ "$n" -ge 1 ] || { echo "$0: N must be at least 1" >&2 && exit 2; }
    case $out in *.prtb) ;; *) echo "$0: OUT must be a .prtb bundle, not '$out'" >&2 && exit 2 ;; esac
}
