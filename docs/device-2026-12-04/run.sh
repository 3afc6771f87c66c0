#!/bin/bash
# Device check (issue 11 throughput, learner NOTES "GPU never run"): actor scaling on 16 cores, GPU learner.
cd "$(dirname "$0")/.."
for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig
[ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ] && export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
python3 -c "import lzma,shutil;shutil.copyfileobj(lzma.open('.devcheck/l3p.xz'),open('/tmp/l3p','wb'))" && chmod +x /tmp/l3p
L=/tmp/l3p; log=$OUT/devcheck.log
exec > >(tee -a $log) 2>&1
lscpu | grep -E "Model name|^CPU\(s\)"; nvidia-smi -L; date
step(){ echo; echo "### $*"; s=$(date +%s%N); timeout ${T:-120} "$@"; echo "### rc=$? wall_ms=$(( ($(date +%s%N)-s)/1000000 ))"; }
export GLIBC_TUNABLES=glibc.malloc.mmap_threshold=268435456:glibc.malloc.trim_threshold=268435456
for t in 1 2 4 8 16; do step $L bench sim --robot a1 --terrain flat --envs 4096 --threads $t --seconds 4; done
L3P_DEVICE=cpu step $L bench learner --config .devcheck/t16.toml --threads 16 --updates 3
T=180 step $L bench learner --config .devcheck/t16.toml --updates 3
L3P_DEVICE=cpu step $L bench learner --envs 4096 --hidden 512,256,128 --threads 16 --updates 2
T=150 step $L bench learner --envs 4096 --hidden 512,256,128 --updates 2
for c in t2 t8 t16 t8x2; do L3P_DEVICE=cpu step $L bench train .devcheck/$c.toml --iterations 7 --warmup 2; done
T=180 step $L bench train .devcheck/t16.toml --iterations 7 --warmup 2
date
