# The parts of the shared mpc dataset (experiments/issue36/make_data.sh), for bc.sh and
# distill_row.sh to source: `parts A` prints set A's files (even k), `parts B` set B's
# (odd k), `parts AB` both, one per line in the glob's order (part_0, part_1, part_10, ..;
# the order the shipped fits concatenated them in).
parts() {
  local f k
  for f in runs/distill_data/part_*/dagger_data.npz; do
    [ -f "$f" ] || continue
    k=${f#runs/distill_data/part_}; k=${k%%/*}
    case $1 in
      A) if ((10#$k % 2 == 0)); then echo "$f"; fi ;;
      B) if ((10#$k % 2 == 1)); then echo "$f"; fi ;;
      AB) echo "$f" ;;
      *) echo "parts: A, B or AB, not $1" >&2; return 2 ;;
    esac
  done
}
