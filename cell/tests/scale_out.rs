//! Scale-out (`deploy/`): the shard entry script is the only shard arithmetic, so it is run the
//! way each scheduler runs it, with the environment the scheduler sets: three SLURM array tasks
//! through `deploy/slurm/cell-run.sbatch`, and the Kubernetes Indexed Job's pods as
//! `deploy/kubernetes/cell-run-job.yaml` declares them (its command, arguments, completions and
//! `CELL_SHARDS`), each followed by its merge step; both merged results must equal a one-process
//! run record for record. The script refuses a missing or inconsistent scheduler environment.
//! The Kubernetes manifests are validated against the Kubernetes schemas with kubernetes-validate
//! (PyPI, pinned, in a venv under `target/` that `scripts/deploy_check/venv.sh` provisions), and
//! `deploy/Containerfile` is checked statically with dockerfile-parse from the same venv: what
//! it copies exists and is in the build context, its pins are the build scripts' pins, the
//! runtime image finds its libraries, and every image path the manifests run is in the image.
//! Building the image itself needs docker or podman, which this test does not.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value as Json;

mod support;

use support::{root, text};

/// Episodes of the sharded runs: a few per shard, so every shard has work.
const EPISODES: u32 = 6;
/// The nominal scenario's results folder (its `name`).
const SCENARIO_NAME: &str = "usbc-nominal";
/// Where the Containerfile puts the repository's files in the image.
const IMAGE_ROOT: &str = "/opt/cell/";
/// Scheduler variables a test process may not inherit from whoever runs the tests.
const SCHEDULER_VARS: [&str; 13] = [
    "SLURM_ARRAY_JOB_ID",
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_MAX",
    "SLURM_ARRAY_TASK_COUNT",
    "SLURM_ARRAY_TASK_STEP",
    "SLURM_CPUS_PER_TASK",
    "SLURM_SUBMIT_DIR",
    "JOB_COMPLETION_INDEX",
    "CELL_SHARDS",
    "CELL_IMAGE",
    "CELL_DEPLOY_DIR",
    "CELL_RUN_ARGS",
];

/// `bash SCRIPT ARGS...` with the built `cell` as `CELL_BIN`, no inherited scheduler variables,
/// and `env` set.
fn bash(script: &Path, args: &[String], env: &[(&str, String)]) -> Command {
    let mut c = Command::new("bash");
    c.arg(script).args(args).current_dir(root());
    for v in SCHEDULER_VARS {
        c.env_remove(v);
    }
    c.env("CELL_BIN", env!("CARGO_BIN_EXE_cell"));
    for (k, v) in env {
        c.env(k, v);
    }
    c
}

/// Runs commands concurrently (as a scheduler would) and asserts each succeeded.
fn run_all(what: &str, commands: Vec<Command>) {
    let children: Vec<_> = commands
        .into_iter()
        .map(|mut c| {
            c.stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped());
            c.spawn().expect("bash runs")
        })
        .collect();
    for (i, child) in children.into_iter().enumerate() {
        let o = child.wait_with_output().unwrap();
        assert!(o.status.success(), "{what} {i} failed:\n{}", text(&o));
    }
}

/// The episode records of a results file, by episode, without the wall-clock field.
fn records(file: &Path) -> Vec<Json> {
    let body =
        std::fs::read_to_string(file).unwrap_or_else(|e| panic!("reading {}: {e}", file.display()));
    let mut v: Vec<Json> = body
        .lines()
        .skip(1)
        .map(|l| {
            let mut r: Json = serde_json::from_str(l).unwrap();
            r.as_object_mut().unwrap().remove("wall_time_s");
            r
        })
        .collect();
    v.sort_by_key(|r| r["episode"].as_u64());
    v
}

/// The shard folders under a scenario's results folder, and the episodes each holds.
fn shard_folders(dir: &Path) -> BTreeMap<String, Vec<u64>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("shard-"))
        .map(|n| {
            let episodes = records(&dir.join(&n).join("episodes.jsonl"))
                .iter()
                .map(|r| r["episode"].as_u64().unwrap())
                .collect();
            (n, episodes)
        })
        .collect()
}

/// What `N` shards of `EPISODES` episodes must leave: `shard-I-of-N` with episodes ≡ I − 1 mod N.
fn expected_shards(n: u32) -> BTreeMap<String, Vec<u64>> {
    (1..=n)
        .map(|i| {
            let episodes = (0..EPISODES)
                .filter(|e| e % n == i - 1)
                .map(u64::from)
                .collect();
            (format!("shard-{i}-of-{n}"), episodes)
        })
        .collect()
}

/// The fields of a Kubernetes Job manifest this test follows. The manifests keep `command` and
/// `args` as one-line lists of double-quoted strings, so each is JSON.
#[derive(Debug)]
struct JobManifest {
    completion_mode: Option<String>,
    completions: Option<u32>,
    parallelism: Option<u32>,
    cell_shards: Option<String>,
    command: Vec<String>,
    args: Vec<String>,
    mount_path: String,
    image: String,
}

/// The Job in a manifest file (its other documents, such as the volume claim, skipped).
fn job_manifest(file: &str) -> JobManifest {
    let path = root().join(file);
    let body = std::fs::read_to_string(&path).unwrap();
    let jobs: Vec<&str> = body
        .split("\n---\n")
        .filter(|d| d.lines().any(|l| l.trim() == "kind: Job"))
        .collect();
    assert_eq!(jobs.len(), 1, "{file}: one Job expected");
    let lines: Vec<&str> = jobs[0].lines().map(str::trim).collect();
    let field = |key: &str| -> Option<String> {
        let found: Vec<&str> = lines
            .iter()
            .filter_map(|l| l.strip_prefix(key))
            .filter_map(|rest| rest.strip_prefix(':'))
            .map(str::trim)
            .collect();
        assert!(
            found.len() <= 1,
            "{file}: {key} appears {} times",
            found.len()
        );
        found.first().map(|s| s.to_string())
    };
    let list = |key: &str| -> Vec<String> {
        let raw = field(key).unwrap_or_else(|| panic!("{file}: no {key}"));
        serde_json::from_str(&raw).unwrap_or_else(|e| {
            panic!("{file}: {key} must be a one-line list of double-quoted strings ({e}): {raw}")
        })
    };
    let cell_shards = lines
        .iter()
        .position(|l| *l == "- name: CELL_SHARDS")
        .map(|i| {
            let value = lines[i + 1]
                .strip_prefix("value:")
                .unwrap_or_else(|| panic!("{file}: CELL_SHARDS has no value on the next line"));
            value.trim().trim_matches('"').to_string()
        });
    JobManifest {
        completion_mode: field("completionMode"),
        completions: field("completions").map(|v| v.parse().unwrap()),
        parallelism: field("parallelism").map(|v| v.parse().unwrap()),
        cell_shards,
        command: list("command"),
        args: list("args"),
        mount_path: field("mountPath").unwrap_or_else(|| panic!("{file}: no mountPath")),
        image: field("image").unwrap_or_else(|| panic!("{file}: no image")),
    }
}

/// The sharded run's Job: Indexed, with completions, parallelism and CELL_SHARDS agreeing.
fn run_job() -> (JobManifest, u32) {
    let job = job_manifest("deploy/kubernetes/cell-run-job.yaml");
    assert_eq!(job.completion_mode.as_deref(), Some("Indexed"), "{job:?}");
    let n = job.completions.expect("completions");
    assert!(n >= 2, "a sharded run has at least 2 shards: {job:?}");
    assert_eq!(
        job.parallelism,
        Some(n),
        "parallelism = completions: {job:?}"
    );
    assert_eq!(
        job.cell_shards.as_deref(),
        Some(n.to_string().as_str()),
        "CELL_SHARDS = completions: {job:?}"
    );
    (job, n)
}

/// A container path on this machine: the image's `/opt/cell/X` is the repository's `X` (the
/// Containerfile test checks that), the Job's volume is `results`.
fn on_host(arg: &str, job: &JobManifest, results: &Path) -> String {
    if let Some(rest) = arg.strip_prefix(IMAGE_ROOT) {
        return root().join(rest).display().to_string();
    }
    if let Some(rest) = arg.strip_prefix(job.mount_path.as_str())
        && (rest.is_empty() || rest.starts_with('/'))
    {
        return format!("{}{rest}", results.display());
    }
    arg.to_string()
}

/// `bash` for a Job's container: its command (a script) and arguments, mapped onto this machine.
fn container(job: &JobManifest, results: &Path, extra: &[&str], env: &[(&str, String)]) -> Command {
    assert_eq!(job.command.len(), 1, "the command is one script: {job:?}");
    let script = PathBuf::from(on_host(&job.command[0], job, results));
    let mut args: Vec<String> = job.args.iter().map(|a| on_host(a, job, results)).collect();
    args.extend(extra.iter().map(|s| s.to_string()));
    bash(&script, &args, env)
}

#[test]
fn slurm_and_kubernetes_shards_merge_into_the_one_process_run() {
    let tmp = tempfile::tempdir().unwrap();
    let episodes = EPISODES.to_string();
    let scenario = support::nominal();

    // The reference: one process, all episodes.
    let whole = tmp.path().join("whole");
    let o = support::cell(&[
        "run",
        &scenario,
        "--out",
        &whole.display().to_string(),
        "--episodes",
        &episodes,
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let reference = records(&whole.join(SCENARIO_NAME).join("all/episodes.jsonl"));
    assert_eq!(reference.len(), EPISODES as usize);
    let reference_summary =
        std::fs::read(whole.join(SCENARIO_NAME).join("all/summary.json")).unwrap();

    // SLURM: `sbatch --array=1-3 cell-run.sbatch` (as `submit.sh SCENARIO OUT 3` submits it);
    // SLURM runs a copy of the batch script, in the submit folder, with these variables.
    let slurm_out = tmp.path().join("slurm");
    let n = 3u32;
    let common = |id: u32| {
        vec![
            ("SLURM_ARRAY_JOB_ID", "4242".to_string()),
            ("SLURM_ARRAY_TASK_ID", id.to_string()),
            ("SLURM_ARRAY_TASK_MIN", "1".to_string()),
            ("SLURM_ARRAY_TASK_MAX", n.to_string()),
            ("SLURM_ARRAY_TASK_COUNT", n.to_string()),
            ("SLURM_ARRAY_TASK_STEP", "1".to_string()),
            ("SLURM_CPUS_PER_TASK", "2".to_string()),
            ("SLURM_SUBMIT_DIR", root().display().to_string()),
            ("CELL_SCENARIO", scenario.clone()),
            ("CELL_OUT", slurm_out.display().to_string()),
            ("CELL_RUN_ARGS", format!("--episodes {EPISODES}")),
        ]
    };
    let sbatch = root().join("deploy/slurm/cell-run.sbatch");
    run_all(
        "SLURM array task",
        (1..=n).map(|id| bash(&sbatch, &[], &common(id))).collect(),
    );
    assert_eq!(
        shard_folders(&slurm_out.join(SCENARIO_NAME)),
        expected_shards(n),
        "SLURM shards"
    );
    let merge = root().join("deploy/slurm/cell-merge.sbatch");
    let env = [
        ("SLURM_SUBMIT_DIR", root().display().to_string()),
        ("CELL_OUT", slurm_out.display().to_string()),
    ];
    run_all("SLURM merge", vec![bash(&merge, &[], &env)]);
    let merged = slurm_out.join(SCENARIO_NAME).join("merged");
    assert_eq!(records(&merged.join("episodes.jsonl")), reference, "SLURM");
    assert_eq!(
        std::fs::read(merged.join("summary.json")).unwrap(),
        reference_summary,
        "SLURM summary"
    );

    // Kubernetes: the Indexed Job's pods, JOB_COMPLETION_INDEX 0..completions, as the manifest
    // declares them; then the merge Job's container.
    let (job, k) = run_job();
    let k8s_out = tmp.path().join("kubernetes");
    std::fs::create_dir_all(&k8s_out).unwrap();
    let shards = job.cell_shards.clone().unwrap();
    run_all(
        "Kubernetes completion index",
        (0..k)
            .map(|index| {
                let env = [
                    ("JOB_COMPLETION_INDEX", index.to_string()),
                    ("CELL_SHARDS", shards.clone()),
                ];
                container(&job, &k8s_out, &["--episodes", &episodes], &env)
            })
            .collect(),
    );
    assert_eq!(
        shard_folders(&k8s_out.join(SCENARIO_NAME)),
        expected_shards(k),
        "Kubernetes shards"
    );
    let merge_job = job_manifest("deploy/kubernetes/cell-merge-job.yaml");
    assert_eq!(
        merge_job.mount_path, job.mount_path,
        "both Jobs mount the results alike"
    );
    assert_eq!(merge_job.image, job.image, "both Jobs run the same image");
    run_all(
        "Kubernetes merge",
        vec![container(&merge_job, &k8s_out, &[], &[])],
    );
    let merged = k8s_out.join(SCENARIO_NAME).join("merged");
    assert_eq!(
        records(&merged.join("episodes.jsonl")),
        reference,
        "Kubernetes"
    );
    assert_eq!(
        std::fs::read(merged.join("summary.json")).unwrap(),
        reference_summary,
        "Kubernetes summary"
    );
}

/// run-shard.sh with `echo` as the binary: what it would run, or its refusal.
fn shard_command(env: &[(&str, &str)]) -> Output {
    let script = root().join("deploy/run-shard.sh");
    let mut c = bash(
        &script,
        &["s.toml".into(), "out".into(), "--quiet".into()],
        &[],
    );
    c.env("CELL_BIN", "echo");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().unwrap()
}

#[test]
fn the_shard_script_maps_each_scheduler_and_refuses_what_does_not_add_up() {
    let runs = |env: &[(&str, &str)], shard: &str| {
        let o = shard_command(env);
        assert!(o.status.success(), "{env:?}: {}", text(&o));
        assert_eq!(
            String::from_utf8_lossy(&o.stdout).trim(),
            format!("run s.toml --shard {shard} --out out --quiet"),
            "{env:?}"
        );
    };
    let slurm = |id: &'static str, min: &'static str, max: &'static str, count: &'static str| {
        [
            ("SLURM_ARRAY_TASK_ID", id),
            ("SLURM_ARRAY_TASK_MIN", min),
            ("SLURM_ARRAY_TASK_MAX", max),
            ("SLURM_ARRAY_TASK_COUNT", count),
        ]
    };
    runs(&slurm("1", "1", "8", "8"), "1/8");
    runs(&slurm("8", "1", "8", "8"), "8/8");
    // An array counted from 0 (--array=0-7) is shifted, not taken as shard 0.
    runs(&slurm("0", "0", "7", "8"), "1/8");
    runs(&slurm("09", "1", "10", "10"), "9/10");
    runs(
        &[("JOB_COMPLETION_INDEX", "0"), ("CELL_SHARDS", "3")],
        "1/3",
    );
    runs(
        &[("JOB_COMPLETION_INDEX", "2"), ("CELL_SHARDS", "3")],
        "3/3",
    );

    let refuses = |env: &[(&str, &str)], says: &str| {
        let o = shard_command(env);
        assert!(!o.status.success(), "{env:?} ran: {}", text(&o));
        assert!(o.stdout.is_empty(), "{env:?} ran: {}", text(&o));
        assert!(text(&o).contains(says), "{env:?}: {}", text(&o));
    };
    refuses(&[], "no scheduler task index");
    refuses(&[("JOB_COMPLETION_INDEX", "1")], "CELL_SHARDS is not");
    refuses(
        &[("JOB_COMPLETION_INDEX", "3"), ("CELL_SHARDS", "3")],
        "not below CELL_SHARDS",
    );
    refuses(
        &[("JOB_COMPLETION_INDEX", "-1"), ("CELL_SHARDS", "3")],
        "not a whole number",
    );
    refuses(
        &[
            ("JOB_COMPLETION_INDEX", "0"),
            ("CELL_SHARDS", "3"),
            ("SLURM_ARRAY_TASK_ID", "1"),
        ],
        "refusing to guess",
    );
    refuses(
        &[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
        ],
        "SLURM_ARRAY_TASK_MIN is not",
    );
    refuses(&slurm("4", "1", "3", "3"), "outside the array");
    // --array=1,2,5 or 1-5:2: three tasks that are not 1-3.
    refuses(&slurm("2", "1", "5", "3"), "contiguous");
    refuses(
        &[
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_MAX", "5"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
        ],
        "contiguous",
    );
    let mut mismatch = slurm("1", "1", "3", "3").to_vec();
    mismatch.push(("CELL_SHARDS", "4"));
    refuses(&mismatch, "CELL_SHARDS is 4");
}

/// The validators' Python (kubernetes-validate, dockerfile-parse), provisioned on first use.
fn validators() -> PathBuf {
    let out = Command::new("bash")
        .arg(root().join("scripts/deploy_check/venv.sh"))
        .output()
        .expect("run scripts/deploy_check/venv.sh");
    assert!(
        out.status.success(),
        "provisioning the deploy-check venv failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    PathBuf::from(String::from_utf8_lossy(&out.stdout).trim())
}

/// The oldest Kubernetes the manifests need (backoffLimitPerIndex) and the newest the validator
/// knows.
const KUBERNETES_VERSIONS: [&str; 2] = ["1.29.0", "1.37.0"];

fn kubernetes_validate(python: &Path, files: &[PathBuf], version: &str) -> Output {
    Command::new(python.with_file_name("kubernetes-validate"))
        .args(["--strict", "--quiet", "--kubernetes-version", version])
        .args(files)
        .output()
        .expect("kubernetes-validate runs")
}

#[test]
fn the_kubernetes_manifests_validate_against_the_kubernetes_schema() {
    let python = validators();
    let dir = root().join("deploy/kubernetes");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "yaml"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 2, "{files:?}");
    for version in KUBERNETES_VERSIONS {
        let o = kubernetes_validate(&python, &files, version);
        assert!(o.status.success(), "Kubernetes {version}: {}", text(&o));
    }
    run_job();

    // The validator does reject a misspelt field and a wrongly typed one.
    let tmp = tempfile::tempdir().unwrap();
    let body = std::fs::read_to_string(dir.join("cell-run-job.yaml")).unwrap();
    for (from, to) in [
        ("completionMode: Indexed", "completionsMode: Indexed"),
        ("claimName: cell-results", "claimName: 3"),
    ] {
        let bad = tmp.path().join("bad.yaml");
        assert!(body.contains(from));
        std::fs::write(&bad, body.replace(from, to)).unwrap();
        let o = kubernetes_validate(&python, &[bad], KUBERNETES_VERSIONS[1]);
        assert!(!o.status.success(), "{to:?} passed: {}", text(&o));
    }
}

/// One instruction of the Containerfile as dockerfile-parse reads it.
#[derive(Debug, Clone)]
struct Instruction {
    instruction: String,
    value: String,
    line: u64,
}

/// `[pub] const NAME: &str = "VALUE";` in a Rust source file.
fn rust_const(file: &str, name: &str) -> String {
    let body = std::fs::read_to_string(root().join(file)).unwrap();
    let prefix = format!("const {name}: &str = \"");
    let line = body
        .lines()
        .find_map(|l| {
            let l = l.trim();
            l.strip_prefix("pub ").unwrap_or(l).strip_prefix(&prefix)
        })
        .unwrap_or_else(|| panic!("{file}: no {prefix}"));
    line.split('"').next().unwrap().to_string()
}

/// Whether `.dockerignore` leaves `path` (relative to the repository) out of the build context.
fn ignored(patterns: &[String], path: &str) -> bool {
    fn glob(pattern: &str, name: &str) -> bool {
        match pattern.split_once('*') {
            None => pattern == name,
            Some((head, tail)) => {
                name.starts_with(head)
                    && (0..=name.len() - head.len()).any(|i| glob(tail, &name[head.len() + i..]))
            }
        }
    }
    let parts: Vec<&str> = path.trim_end_matches('/').split('/').collect();
    patterns.iter().any(|p| {
        let (anywhere, p) = match p.strip_prefix("**/") {
            Some(rest) => (true, rest),
            None => (false, p.as_str()),
        };
        let pp: Vec<&str> = p.split('/').collect();
        let starts: Vec<usize> = if anywhere {
            (0..parts.len()).collect()
        } else {
            vec![0]
        };
        starts.into_iter().any(|s| {
            parts.len() >= s + pp.len() && pp.iter().zip(&parts[s..]).all(|(a, b)| glob(a, b))
        })
    })
}

#[test]
fn the_containerfile_builds_from_what_the_repository_holds() {
    let r = root();
    // The shell scripts parse, and the ones the image and the schedulers run are executable.
    let scripts = [
        "deploy/run-shard.sh",
        "deploy/merge.sh",
        "deploy/slurm/cell-run.sbatch",
        "deploy/slurm/cell-merge.sbatch",
        "deploy/slurm/submit.sh",
        "scripts/deploy_check/venv.sh",
    ];
    for s in scripts {
        let o = Command::new("bash")
            .arg("-n")
            .arg(r.join(s))
            .output()
            .unwrap();
        assert!(o.status.success(), "bash -n {s}: {}", text(&o));
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(r.join(s)).unwrap().permissions().mode();
        assert!(mode & 0o111 == 0o111, "{s} is not executable ({mode:o})");
        // What a checkout gets: the mode git records.
        let o = Command::new("git")
            .args(["ls-files", "--stage", s])
            .current_dir(&r)
            .output()
            .unwrap();
        let staged = String::from_utf8_lossy(&o.stdout);
        assert!(
            staged.is_empty() || staged.starts_with("100755"),
            "git records {s} as not executable: {staged}"
        );
    }

    let python = validators();
    let parse = "import json, sys; from dockerfile_parse import DockerfileParser as P; \
                 d = P(fileobj=open(sys.argv[1], 'rb')); \
                 print(json.dumps({'structure': d.structure, 'envs': d.envs, \
                 'parents': d.parent_images}))";
    let o = Command::new(&python)
        .args(["-c", parse])
        .arg(r.join("deploy/Containerfile"))
        .output()
        .unwrap();
    assert!(o.status.success(), "dockerfile-parse: {}", text(&o));
    let parsed: Json = serde_json::from_slice(&o.stdout).unwrap();
    let all: Vec<Instruction> = parsed["structure"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| Instruction {
            instruction: i["instruction"].as_str().unwrap().to_string(),
            value: i["value"].as_str().unwrap().to_string(),
            line: i["startline"].as_u64().unwrap() + 1,
        })
        .filter(|i| i.instruction != "COMMENT")
        .collect();

    // Global build arguments (before the first FROM), then the stages by name.
    let first_from = all.iter().position(|i| i.instruction == "FROM").unwrap();
    let args: BTreeMap<String, String> = all[..first_from]
        .iter()
        .filter(|i| i.instruction == "ARG")
        .filter_map(|i| i.value.split_once('='))
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    let mut stages: Vec<(String, String, Vec<Instruction>)> = Vec::new();
    for i in &all[first_from..] {
        if i.instruction == "FROM" {
            let (image, name) = i.value.split_once(" AS ").expect("every stage is named");
            stages.push((image.to_string(), name.to_string(), Vec::new()));
        } else {
            stages.last_mut().unwrap().2.push(i.clone());
        }
    }
    let names: Vec<&str> = stages.iter().map(|s| s.1.as_str()).collect();
    assert_eq!(names, ["builder", "runtime"], "stages");
    let parents: Vec<&str> = parsed["parents"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_str().unwrap())
        .collect();
    assert!(
        parents[0].contains("/rust:"),
        "builder from a Rust image: {parents:?}"
    );
    assert!(
        parents[1].ends_with("-slim"),
        "runtime from a slim image: {parents:?}"
    );
    let release = |p: &str| p.rsplit(['-', ':']).next().map(str::to_string);
    assert_eq!(
        release(parents[0]),
        release(parents[1].trim_end_matches("-slim")),
        "builder and runtime on the same Debian release (the binary's glibc): {parents:?}"
    );

    // The pins are the build scripts' pins.
    let onnx = "perception/src/onnx/provision.rs";
    for (arg, constant) in [
        ("ORT_VERSION", "ORT_VERSION"),
        ("ORT_WHEEL", "WHEEL"),
        ("ORT_WHEEL_SHA256", "WHEEL_SHA256"),
        ("ORT_LIBRARY_SHA256", "LIBRARY_SHA256"),
    ] {
        assert_eq!(args.get(arg), Some(&rust_const(onnx, constant)), "{arg}");
    }
    let ort_version = &args["ORT_VERSION"];
    assert_eq!(
        format!("onnxruntime/capi/libonnxruntime.so.{ort_version}"),
        rust_const(onnx, "LIBRARY_IN_WHEEL")
    );
    assert_eq!(
        args.get("MUJOCO_LIBRARY"),
        Some(&rust_const("mujoco-provision/build.rs", "LIB")),
        "MUJOCO_LIBRARY"
    );

    // Everything copied from the build context exists and is not left out of it; the builder
    // gets every workspace member.
    let ignore: Vec<String> = std::fs::read_to_string(r.join(".dockerignore"))
        .unwrap()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(str::to_string)
        .collect();
    assert!(ignored(&ignore, "target") && ignored(&ignore, "robots/fuzz/target"));
    let mut copied: BTreeSet<String> = BTreeSet::new();
    // The runtime image's paths, to the repository paths they come from.
    let mut image_paths: Vec<(String, String)> = Vec::new();
    for (_, stage, instructions) in &stages {
        for i in instructions {
            assert_ne!(i.instruction, "ADD", "line {}: COPY, not ADD", i.line);
            if i.instruction != "COPY" {
                continue;
            }
            let words: Vec<&str> = i.value.split_whitespace().collect();
            let (dest, sources) = words.split_last().unwrap();
            if let Some(from) = sources[0].strip_prefix("--from=") {
                assert_eq!(from, "builder", "line {}", i.line);
                let builder_runs: String = stages[0]
                    .2
                    .iter()
                    .filter(|i| i.instruction == "RUN")
                    .map(|i| i.value.as_str())
                    .collect();
                for s in &sources[1..] {
                    assert!(
                        builder_runs.contains(s),
                        "line {}: no builder step makes {s}",
                        i.line
                    );
                }
                continue;
            }
            for s in sources {
                assert!(!s.starts_with("--"), "line {}: {s}", i.line);
                assert!(
                    r.join(s).exists(),
                    "line {}: {s} is not in the repository",
                    i.line
                );
                assert!(
                    !ignored(&ignore, s),
                    "line {}: .dockerignore leaves {s} out",
                    i.line
                );
                copied.insert(s.trim_end_matches('/').to_string());
                if stage == "runtime" {
                    let target = if dest.ends_with('/') {
                        let name = Path::new(s).file_name().unwrap().to_string_lossy();
                        format!("{dest}{name}")
                    } else {
                        dest.to_string()
                    };
                    image_paths.push((target, s.to_string()));
                }
            }
        }
    }
    let workspace: toml::Table = std::fs::read_to_string(r.join("Cargo.toml"))
        .unwrap()
        .parse()
        .unwrap();
    let members = workspace["workspace"]["members"].as_array().unwrap();
    for needed in
        members
            .iter()
            .map(|m| m.as_str().unwrap())
            .chain(["Cargo.toml", "Cargo.lock", ".cargo"])
    {
        assert!(copied.contains(needed), "the builder does not get {needed}");
    }

    // The runtime image finds its libraries: libmujoco on LD_LIBRARY_PATH (the binary's rpath
    // names the builder's target folder), ONNX Runtime by ORT_DYLIB_PATH.
    let builder_runs: String = stages[0]
        .2
        .iter()
        .filter(|i| i.instruction == "RUN")
        .map(|i| i.value.clone())
        .collect();
    assert!(builder_runs.contains("cargo build --release --locked -p cell"));
    assert!(builder_runs.contains("/opt/cell/lib/${MUJOCO_LIBRARY}"));
    assert!(builder_runs.contains("/opt/cell/lib/libonnxruntime.so.${ORT_VERSION}"));
    let envs = &parsed["envs"];
    let lib_path = envs["LD_LIBRARY_PATH"].as_str().unwrap_or_default();
    assert!(
        lib_path.split(':').any(|d| d == "/opt/cell/lib"),
        "LD_LIBRARY_PATH={lib_path}"
    );
    assert_eq!(
        envs["ORT_DYLIB_PATH"].as_str(),
        Some(format!("/opt/cell/lib/libonnxruntime.so.{ort_version}").as_str())
    );
    assert_eq!(envs["CELL_BIN"].as_str(), Some("/opt/cell/bin/cell"));

    // Every image path the Jobs run is in the image, and it is the repository's file of the same
    // name under /opt/cell (what the sharding test runs in its place).
    let in_image = |p: &str| -> PathBuf {
        let (dest, src) = image_paths
            .iter()
            .filter(|(dest, _)| p == dest || p.starts_with(&format!("{dest}/")))
            .max_by_key(|(dest, _)| dest.len())
            .unwrap_or_else(|| panic!("{p} is not in the image: {image_paths:?}"));
        match p[dest.len()..].trim_start_matches('/') {
            "" => r.join(src),
            rest => r.join(src).join(rest),
        }
    };
    for file in [
        "deploy/kubernetes/cell-run-job.yaml",
        "deploy/kubernetes/cell-merge-job.yaml",
    ] {
        let job = job_manifest(file);
        for p in job.command.iter().chain(&job.args) {
            let Some(rest) = p.strip_prefix(IMAGE_ROOT) else {
                continue;
            };
            let host = in_image(p);
            assert!(
                host.exists(),
                "{file}: {p} is {} here, which does not exist",
                host.display()
            );
            assert_eq!(host, r.join(rest), "{file}: {p}");
        }
        assert!(
            job.command[0].starts_with(IMAGE_ROOT),
            "{file}: {:?}",
            job.command
        );
    }

    // The SLURM batch script is an array counted from 1 (submit.sh sets its size).
    let sbatch = std::fs::read_to_string(r.join("deploy/slurm/cell-run.sbatch")).unwrap();
    assert!(sbatch.lines().any(|l| l.starts_with("#SBATCH --array=1-")));
}

#[test]
fn slurm_submit_queues_the_array_and_then_its_merge() {
    // A stand-in `sbatch` that records its arguments and the variables the batch scripts read.
    let tmp = tempfile::tempdir().unwrap();
    let bin = tmp.path().join("bin");
    std::fs::create_dir_all(&bin).unwrap();
    let log = tmp.path().join("sbatch.log");
    let fake = format!(
        "#!/usr/bin/env bash\n\
         n=$(($(wc -l < {log:?} 2>/dev/null || echo 0) + 1))\n\
         echo \"$* | $CELL_SCENARIO | $CELL_OUT | $CELL_RUN_ARGS | $CELL_DEPLOY_DIR\" >> {log:?}\n\
         echo \"$((4241 + n));cluster\"\n"
    );
    std::fs::write(bin.join("sbatch"), fake).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(bin.join("sbatch"), std::fs::Permissions::from_mode(0o755)).unwrap();
    let out = tmp.path().join("runs");
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap());
    let args: Vec<String> = [
        "scenarios/usbc_nominal.toml",
        &out.display().to_string(),
        "5",
        "--episodes",
        "100",
    ]
    .map(String::from)
    .to_vec();
    let o = bash(
        &root().join("deploy/slurm/submit.sh"),
        &args,
        &[("PATH", path)],
    )
    .output()
    .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("job array 4242") && text(&o).contains("merge: job 4243"));
    let calls: Vec<String> = std::fs::read_to_string(&log)
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    let r = root();
    let env = format!(
        "| {} | {} | --episodes 100 | {}",
        r.join("scenarios/usbc_nominal.toml").display(),
        out.display(),
        r.join("deploy").display()
    );
    assert_eq!(
        calls,
        [
            format!(
                "--parsable --array=1-5 {} {env}",
                r.join("deploy/slurm/cell-run.sbatch").display()
            ),
            format!(
                "--parsable --dependency=afterok:4242 --kill-on-invalid-dep=yes {} {env}",
                r.join("deploy/slurm/cell-merge.sbatch").display()
            ),
        ]
    );
}
