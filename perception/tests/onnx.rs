//! A real ONNX model through ort: the committed fixture (conv 3→2, 3×3, stride 2, pad 1, bias → relu,
//! plus a global average pool) checked against the same convolution computed by hand here, in
//! batches through one reused session; and the manifest checks (checksum, corrupt file, signature).
//! ONNX Runtime is provisioned on first use from the pinned wheel (cached, see `perception::onnx`).

use perception::onnx::{BatchSession, ModelManifest, OnnxError, Runtime};
use std::path::{Path, PathBuf};

const SIZE: usize = 128;
const OUT: usize = 64;

fn fixture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/onnx")
}

fn runtime() -> Runtime {
    Runtime::get().unwrap_or_else(|e| panic!("{e}"))
}

/// The fixture's weights, by the generator's formula, and its biases.
fn weight(o: usize, c: usize, ky: usize, kx: usize) -> f64 {
    0.5 * ((1 + 27 * o + 9 * c + 3 * ky + kx) as f64).sin()
}
const BIAS: [f64; 2] = [0.1, -0.2];

/// A crop with structure in every channel, different per `seed`.
fn crop(seed: usize) -> Vec<f32> {
    (0..3 * SIZE * SIZE)
        .map(|i| {
            let (c, y, x) = (i / (SIZE * SIZE), (i / SIZE) % SIZE, i % SIZE);
            ((0.07 * x as f64 + 0.05 * y as f64 * (c + 1) as f64 + seed as f64).sin()
                + 0.3 * ((x * y + 7 * seed + c) % 5) as f64
                - 0.4) as f32
        })
        .collect()
}

/// Conv (stride 2, zero padding 1) + bias + relu, by hand: [2][64][64].
fn conv_relu(input: &[f32]) -> Vec<f64> {
    let mut out = vec![0.0; 2 * OUT * OUT];
    for o in 0..2 {
        for y in 0..OUT {
            for x in 0..OUT {
                let mut acc = BIAS[o];
                for c in 0..3 {
                    for ky in 0..3 {
                        for kx in 0..3 {
                            let (iy, ix) = ((2 * y + ky) as isize - 1, (2 * x + kx) as isize - 1);
                            if (0..SIZE as isize).contains(&iy) && (0..SIZE as isize).contains(&ix)
                            {
                                let v = input[c * SIZE * SIZE + iy as usize * SIZE + ix as usize];
                                acc += weight(o, c, ky, kx) * v as f64;
                            }
                        }
                    }
                }
                out[o * OUT * OUT + y * OUT + x] = acc.max(0.0);
            }
        }
    }
    out
}

fn max_abs_diff(a: &[f32], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(&x, &y)| (x as f64 - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn batches_through_one_session_match_the_convolution_by_hand() {
    let rt = runtime();
    let mut session = BatchSession::open(&rt, &fixture_dir().join("conv_fixture.toml"), 2).unwrap();
    assert_eq!(session.item_len(), 3 * SIZE * SIZE);
    let crops: Vec<Vec<f32>> = (0..3).map(crop).collect();
    // A batch of three, then a batch of one through the same session and buffers.
    for batch in [vec![0, 1, 2], vec![2]] {
        let items: Vec<&[f32]> = batch.iter().map(|&i| crops[i].as_slice()).collect();
        let outputs = session.run(&items).unwrap();
        assert_eq!(outputs.len(), 2);
        let (features, pooled) = (&outputs[0], &outputs[1]);
        assert_eq!(features.name, "features");
        assert_eq!(features.shape, vec![batch.len(), 2, OUT, OUT]);
        assert_eq!(pooled.shape, vec![batch.len(), 2, 1, 1]);
        for (k, &i) in batch.iter().enumerate() {
            let expected = conv_relu(&crops[i]);
            let positive = expected.iter().filter(|&&v| v > 0.0).count();
            assert!(
                positive > 1000 && positive < expected.len() - 1000,
                "the relu must cut: {positive}"
            );
            let err = max_abs_diff(features.item(k), &expected);
            assert!(err < 1e-4, "crop {i}: features differ by {err}");
            let mean: Vec<f64> = expected
                .chunks(OUT * OUT)
                .map(|ch| ch.iter().sum::<f64>() / (OUT * OUT) as f64)
                .collect();
            let err = max_abs_diff(pooled.item(k), &mean);
            assert!(
                err < 1e-5,
                "crop {i}: pooled {:?} vs {mean:?}",
                pooled.item(k)
            );
        }
    }
}

#[test]
fn a_batch_item_of_the_wrong_size_is_refused_with_the_model_named() {
    let mut session =
        BatchSession::open(&runtime(), &fixture_dir().join("conv_fixture.toml"), 1).unwrap();
    let short = vec![0.0f32; 3 * 64 * 64];
    let err = session.run(&[&short]).unwrap_err().to_string();
    assert!(
        err.contains("conv_fixture.onnx") && err.contains("batch item 0 has 12288 values"),
        "{err}"
    );
    assert!(
        session
            .run(&[])
            .unwrap_err()
            .to_string()
            .contains("empty batch")
    );
}

/// Copies the fixture into a temp dir with the manifest edited by `edit`, and the model bytes by `bytes`.
fn variant(
    edit: impl Fn(String) -> String,
    bytes: impl Fn(Vec<u8>) -> Vec<u8>,
) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let manifest = std::fs::read_to_string(fixture_dir().join("conv_fixture.toml")).unwrap();
    let model = std::fs::read(fixture_dir().join("conv_fixture.onnx")).unwrap();
    let path = dir.path().join("conv_fixture.toml");
    std::fs::write(&path, edit(manifest)).unwrap();
    std::fs::write(dir.path().join("conv_fixture.onnx"), bytes(model)).unwrap();
    (dir, path)
}

fn open_err(manifest: &Path) -> String {
    match BatchSession::open(&runtime(), manifest, 1) {
        Ok(_) => panic!("{} opened", manifest.display()),
        Err(e) => e.to_string(),
    }
}

fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

#[test]
fn a_model_whose_checksum_differs_from_the_manifest_is_refused() {
    let (_dir, path) = variant(
        |m| m,
        |mut b| {
            let n = b.len();
            b[n - 3] ^= 0x01;
            b
        },
    );
    let err = open_err(&path);
    assert!(
        err.contains("conv_fixture.onnx: sha256 is") && err.contains("a15d2b51"),
        "{err}"
    );
}

#[test]
fn a_corrupt_model_with_a_matching_checksum_is_refused_by_onnx_runtime() {
    let model = std::fs::read(fixture_dir().join("conv_fixture.onnx")).unwrap();
    let truncated = model[..model.len() / 2].to_vec();
    let sha = sha256_hex(&truncated);
    let (_dir, path) = variant(
        |m| {
            m.replace(
                "a15d2b5113df6247db2cf9a9e28658e0c04a4a7e883d30fbd82033a24fba684f",
                &sha,
            )
        },
        |_| truncated.clone(),
    );
    let err = open_err(&path);
    assert!(
        err.contains("conv_fixture.onnx: ONNX Runtime cannot load this model"),
        "{err}"
    );
}

#[test]
fn a_missing_model_is_named() {
    let (dir, path) = variant(|m| m, |b| b);
    std::fs::remove_file(dir.path().join("conv_fixture.onnx")).unwrap();
    let err = open_err(&path);
    assert!(
        err.contains("conv_fixture.onnx") && err.contains("No such file"),
        "{err}"
    );
}

#[test]
fn shapes_names_and_counts_that_differ_from_the_manifest_are_named() {
    let cases = [
        (
            "shape = [-1, 3, 128, 128]",
            "shape = [-1, 3, 64, 64]",
            "input 0 differs",
            "crops: shape: manifest [-1, 3, 64, 64], model [-1, 3, 128, 128]",
        ),
        (
            "shape = [-1, 2, 1, 1]",
            "shape = [-1, 2, 2, 2]",
            "output 1 differs",
            "pooled: shape",
        ),
        (
            "name = \"features\"",
            "name = \"heatmap\"",
            "output 0 differs",
            "name: manifest \"heatmap\", model \"features\"",
        ),
        (
            "[[outputs]]\nname = \"pooled\"\nshape = [-1, 2, 1, 1]\ndtype = \"f32\"\n",
            "",
            "output count differs",
            "manifest lists 1, model has 2",
        ),
    ];
    for (from, to, what, detail) in cases {
        let (_dir, path) = variant(
            |m| {
                assert!(m.contains(from));
                m.replace(from, to)
            },
            |b| b,
        );
        let err = open_err(&path);
        assert!(
            err.contains("conv_fixture.onnx") && err.contains(what) && err.contains(detail),
            "{err}"
        );
        assert!(err.contains("conv_fixture.toml"), "{err}");
    }
}

#[test]
fn a_malformed_manifest_names_file_line_and_column() {
    let (_dir, path) = variant(|m| m.replace("opset = 17", "opset = \"seventeen\""), |b| b);
    let err = ModelManifest::load(&path).unwrap_err();
    let OnnxError::Manifest { line, column, .. } = err else {
        panic!("{err}")
    };
    assert_eq!((line, column), (6, 9), "{err}");
    let (_dir, path) = variant(|m| m.replace("sha256 = \"a15d", "sha256 = \"zz5d"), |b| b);
    let err = ModelManifest::load(&path).unwrap_err().to_string();
    assert!(
        err.contains("conv_fixture.toml:5:1: sha256 must be 64 hex digits"),
        "{err}"
    );
}
