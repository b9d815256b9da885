#!/bin/sh
# Regenerates the small runs of desktop/tcomp/tests/diagnose_fit.rs (run
# from anywhere; paths are taken from the repository root):
# simulated with `tcomp sim`, then written the way measured data sets are:
# sensors renamed T01..T16 -> T_T0..T_T15, a T_ambient column (the machine's
# constant 20 degC nominal ambient), no coolant_on column; the
# norpm run also lacks spindle_rpm and feed_activity.
set -e
cd "$(dirname "$0")/../../../../.."
out=desktop/tcomp/tests/data/diagnose-fit
tcomp=${TCOMP:-target/debug/tcomp}
sim() { # duty seed name
  $tcomp sim examples/machines/turning-center-16.toml --duty "examples/duty/$1" --hours 4 \
    --sample-period 60 --seed "$2" -o "$out/$3.sim.csv"
}
# keep `#` metadata; rename and drop columns by header name
reshape() { # name drop-regex
  awk -F, -v OFS=, -v drop="$2" '
    /^#/ { print; next }
    !hdr { hdr = 1
      for (i = 1; i <= NF; i++) {
        n = $i
        if (n ~ /^T[0-9][0-9]$/) n = sprintf("T_T%d", substr(n, 2) - 1)
        keep[i] = (n !~ drop); name[i] = n
      }
      line = ""; for (i = 1; i <= NF; i++) if (keep[i]) line = line (line == "" ? "" : ",") name[i]
      print line ",T_ambient"; next }
    { line = ""; for (i = 1; i <= NF; i++) if (keep[i]) line = line (line == "" ? "" : ",") $i
      print line ",20" }' "$out/$1.sim.csv" > "$out/$1.csv"
  rm "$out/$1.sim.csv"
}
sim warmup-steps.toml 41 warm-a
sim production-mixed.toml 42 mixed-b
sim warmup-steps.toml 43 norpm-a
reshape warm-a '^coolant_on$'
reshape mixed-b '^coolant_on$'
reshape norpm-a '^(coolant_on|spindle_rpm|feed_activity)$'
