//! The sharded bake through a real scheduler: `deploy/slurm/test.sh` starts a single-node Slurm
//! (munge, slurmctld, slurmd on this machine, under a temporary directory), submits with
//! `deploy/slurm/submit.sh` the plan, a 4-task array of shards of `maze --size 256` (one of them
//! requeued while it runs, as Slurm does on a node failure) and the dependent merge, and checks
//! that every file of a single-process bake is byte-identical in the merged directory. It needs
//! root and Debian's `slurm-wlm` and `munge` (the README's test command installs them) and fails,
//! naming what is missing, without them.

use std::path::Path;

#[test]
fn a_sharded_bake_through_slurm_is_byte_identical_to_one_process() {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../deploy/slurm/test.sh");
    let out = std::process::Command::new("bash")
        .arg(&script)
        .arg(env!("CARGO_BIN_EXE_ortm"))
        .output()
        .expect("bash runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{text}");
    assert!(
        out.status.success() && text.contains("test.sh: PASS"),
        "deploy/slurm/test.sh failed ({}):\n{text}",
        out.status
    );
    assert!(text.contains("byte-identical"), "{text}");
}
