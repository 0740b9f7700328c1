//! The keypoint net over all crops of a frame in one batched call, then PVNet voting per crop
//! (foreground = mask logit > 0) on the 64 × 64 stride-2 field, spread over threads. Voted
//! positions p of the field become crop pixels (2·p.x + 0.5, 2·p.y + 0.5), covariances × 4.

use nalgebra::Point2;

use super::LearnedError;
use super::crops::CropBatch;
use super::models::{CROP_SIZE, FIELD_SIZE, output_index};
use crate::onnx::{BatchSession, OutputTensor};
use crate::voting::{KeypointVote, VectorField, VoteError, Voter, VotingConfig};

/// The keypoint network with its session, voters (one per thread) and mask buffers.
pub struct KeypointNet {
    session: BatchSession,
    mask: usize,
    vectors: usize,
    keypoints: usize,
    workers: Vec<(Voter, Vec<u8>)>,
}

/// Field cell → crop pixel (stride 2, cell (i, j) centre at crop pixel (2j + 0.5, 2i + 0.5)).
pub fn field_to_crop(vote: &KeypointVote) -> KeypointVote {
    let stride = (CROP_SIZE / FIELD_SIZE) as f64;
    KeypointVote {
        position: Point2::new(
            stride * vote.position.x + 0.5,
            stride * vote.position.y + 0.5,
        ),
        covariance: vote.covariance * (stride * stride),
        ..*vote
    }
}

impl KeypointNet {
    /// Wraps an opened, contract-checked keypoint-net session; votes on `threads` threads.
    pub fn new(session: BatchSession, voting: VotingConfig, threads: usize) -> Self {
        let m = session.manifest();
        let mask = output_index(m, "mask").unwrap_or(0);
        let vectors = output_index(m, "vectors").unwrap_or(1);
        let keypoints = (m.outputs[vectors].shape[1] / 2) as usize;
        Self {
            session,
            mask,
            vectors,
            keypoints,
            workers: (0..threads.max(1))
                .map(|_| (Voter::new(voting), Vec::new()))
                .collect(),
        }
    }

    /// Runs the network on the batch (the `keypoint_net` stage).
    pub fn infer(&mut self, batch: &CropBatch) -> Result<(), LearnedError> {
        let n = batch.len();
        self.session.run_shaped(&batch.shape(), batch.data())?;
        let outputs = self.session.outputs();
        let field = FIELD_SIZE;
        for (index, channels) in [(self.mask, 1), (self.vectors, 2 * self.keypoints)] {
            let out = &outputs[index];
            if out.shape != [n, channels, field, field] {
                return Err(LearnedError::Output {
                    model: self.session.manifest().model_path(),
                    output: out.name.clone(),
                    message: format!(
                        "shape {:?}, expected {:?}",
                        out.shape,
                        [n, channels, field, field]
                    ),
                });
            }
        }
        Ok(())
    }

    /// Votes the keypoints of each of the last batch's `n` crops, in crop pixels (the `voting`
    /// stage); a crop whose field gives no keypoints gets the voting error.
    pub fn vote(&mut self, n: usize) -> Vec<Result<Vec<KeypointVote>, VoteError>> {
        let outputs = self.session.outputs();
        let (mask, vectors) = (&outputs[self.mask], &outputs[self.vectors]);
        let keypoints = self.keypoints;
        let threads = self.workers.len().min(n.max(1));
        let mut results: Vec<Option<Result<Vec<KeypointVote>, VoteError>>> = vec![None; n];
        if threads <= 1 {
            let (voter, buf) = &mut self.workers[0];
            for (i, r) in results.iter_mut().enumerate() {
                *r = Some(vote_one(voter, buf, mask, vectors, keypoints, i));
            }
        } else {
            let mut slots: Vec<Vec<(usize, &mut Option<_>)>> =
                (0..threads).map(|_| Vec::new()).collect();
            for (i, r) in results.iter_mut().enumerate() {
                slots[i % threads].push((i, r));
            }
            std::thread::scope(|s| {
                for ((voter, buf), slot) in self.workers.iter_mut().zip(slots) {
                    s.spawn(move || {
                        for (i, r) in slot {
                            *r = Some(vote_one(voter, buf, mask, vectors, keypoints, i));
                        }
                    });
                }
            });
        }
        results
            .into_iter()
            .map(|r| r.unwrap_or(Err(VoteError::EmptyMask)))
            .collect()
    }
}

fn vote_one(
    voter: &mut Voter,
    buf: &mut Vec<u8>,
    mask: &OutputTensor,
    vectors: &OutputTensor,
    keypoints: usize,
    i: usize,
) -> Result<Vec<KeypointVote>, VoteError> {
    buf.clear();
    buf.extend(mask.item(i).iter().map(|&l| u8::from(l > 0.0)));
    let field = VectorField {
        width: FIELD_SIZE,
        height: FIELD_SIZE,
        keypoints,
        mask: buf,
        vectors: vectors.item(i),
    };
    Ok(voter.vote(&field)?.iter().map(field_to_crop).collect())
}
