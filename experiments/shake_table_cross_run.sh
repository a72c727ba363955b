#!/bin/bash
# Shake-table models identified on whole runs, one and two at once (train.py data.runs=[...]), each
# predicting the runs it never saw from rest (predict.py); results/real/shake_table_cross_run.md. Resumable.
cd "$(dirname "$0")/.."
PY=.venv/bin/python
OUT=outputs/shake_table_cross_run
mkdir -p $OUT
ident() { # name path runs n_storeys
  local name=$1 path=$2 runs=$3 n=$4
  [ -f $OUT/$name/run/complete.json ] && return
  $PY train.py data=xsens "data.path=$path" "data.runs=$runs" system=shear_building system.n_storeys=$n \
     data.hold_out=false 'model.refine.starts=[data]' 'baselines.run=[]' baselines.cramer_rao=false \
     trainer.enable_progress_bar=false hydra.run.dir=$OUT/$name/run > $OUT/$name.train.log 2>&1
  echo "$name identified: exit $? $(date +%T)"
}
pred() { # name path run
  local name=$1 path=$2 run=$3
  local d=$OUT/$name/pred_$(echo $run | tr ' ' '_')
  [ -f $d/prediction.json ] && return
  $PY predict.py run=$OUT/$name/run data=xsens "data.path=$path" "data.run=$run" hydra.run.dir=$d > $d.log 2>&1
  echo "$name -> $run: $(cat $d/prediction.json 2>/dev/null | head -c 300)"
}
F="data/mini_shake_table/Flexible 3 story"
S="data/mini_shake_table/Stiff 1 story"
S3="data/mini_shake_table/Stiff 3 story"
ident s1_nr "$S" "[Northridge Trial 1]" 1
ident s1_nr_ec "$S" "[Northridge Trial 1,El Centro Trial 1]" 1
for r in "El Centro Trial 1" "El Centro Trial 2" "Sine Wave Trial 1" "Sine Wave Trial 2"; do pred s1_nr "$S" "$r"; done
for r in "El Centro Trial 2" "Sine Wave Trial 1" "Sine Wave Trial 2"; do pred s1_nr_ec "$S" "$r"; done
ident f3_nr "$F" "[Northridge]" 3
for r in "Sine 1.0" "Sine 1.5"; do pred f3_nr "$F" "$r"; done
ident f3_nr_s10 "$F" "[Northridge,Sine 1.0]" 3
pred f3_nr_s10 "$F" "Sine 1.5"
ident f3_nr_s15 "$F" "[Northridge,Sine 1.5]" 3
pred f3_nr_s15 "$F" "Sine 1.0"
ident s3_nr "$S3" "[Northridge]" 3
pred s3_nr "$S3" "Sine 1.5"
echo all done
