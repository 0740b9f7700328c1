//! What a render produces: linear radiance, depth, visible instance ids and full masks.

/// A rectangle of pixels of the camera image: columns x0..x0+width, rows y0..y0+height.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// First column.
    pub x0: u32,
    /// First row.
    pub y0: u32,
    /// Number of columns.
    pub width: u32,
    /// Number of rows.
    pub height: u32,
}

impl Window {
    /// The whole image of a camera of this size.
    pub fn full(width: u32, height: u32) -> Self {
        Self {
            x0: 0,
            y0: 0,
            width,
            height,
        }
    }

    /// A `size` × `size` window centred (to the nearest pixel) on (u, v), shifted to stay inside an
    /// image of `width` × `height`.
    pub fn centred(u: f64, v: f64, size: u32, width: u32, height: u32) -> Self {
        let half = size as f64 / 2.0;
        let clamp = |c: f64, n: u32| -> u32 {
            let start = (c - half + 0.5).floor().max(0.0) as u32;
            start.min(n.saturating_sub(size))
        };
        Self {
            x0: clamp(u, width),
            y0: clamp(v, height),
            width: size.min(width),
            height: size.min(height),
        }
    }

    /// The pixels of `self` within `margin` pixels of the image-plane box from (u0, v0) to
    /// (u1, v1), whole pixels, clamped to `self`.
    pub(crate) fn around(&self, [u0, v0, u1, v1]: [f64; 4], margin: f64) -> Window {
        let (wx0, wy0) = (self.x0 as f64, self.y0 as f64);
        let (wx1, wy1) = (wx0 + self.width as f64, wy0 + self.height as f64);
        let x0 = (u0 - margin).floor().clamp(wx0, wx1);
        let y0 = (v0 - margin).floor().clamp(wy0, wy1);
        let x1 = (u1 + margin).ceil().clamp(wx0, wx1);
        let y1 = (v1 + margin).ceil().clamp(wy0, wy1);
        Window {
            x0: x0 as u32,
            y0: y0 as u32,
            width: (x1 - x0) as u32,
            height: (y1 - y0) as u32,
        }
    }

    /// Number of pixels.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Whether the window has no pixels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The full (unoccluded) silhouette of one instance, as a bitmap over a sub-window.
#[derive(Debug, Clone, PartialEq)]
pub struct InstanceMask {
    /// The sub-window (camera pixel coordinates) the bitmap covers.
    pub window: Window,
    /// Row-major, true where the instance covers the pixel centre.
    pub bits: Vec<bool>,
}

impl InstanceMask {
    /// Number of covered pixels.
    pub fn count(&self) -> usize {
        self.bits.iter().filter(|b| **b).count()
    }

    /// Whether camera pixel (x, y) is covered.
    pub fn contains(&self, x: u32, y: u32) -> bool {
        let w = &self.window;
        x >= w.x0
            && y >= w.y0
            && x < w.x0 + w.width
            && y < w.y0 + w.height
            && self.bits[((y - w.y0) * w.width + (x - w.x0)) as usize]
    }
}

/// One render: per pixel of the window, linear RGB radiance, depth and the visible instance.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOutput {
    /// The rendered pixels, in camera image coordinates.
    pub window: Window,
    /// Linear RGB radiance, row-major, supersampled.
    pub radiance: Vec<[f32; 3]>,
    /// Depth (camera-frame z of the surface at the pixel centre), metres; 0 where nothing is hit.
    pub depth: Vec<f64>,
    /// Instance seen at the pixel centre: 0 for none (board, table, background), i + 1 for
    /// instance i (the parts, then any distractors).
    pub visible: Vec<u16>,
    /// Full silhouettes per instance (empty when not requested).
    pub full_masks: Vec<InstanceMask>,
}

impl RenderOutput {
    /// Number of window pixels where instance `i` is visible.
    pub fn visible_count(&self, i: usize) -> usize {
        let id = (i + 1) as u16;
        self.visible.iter().filter(|v| **v == id).count()
    }

    /// Index into the row-major buffers of camera pixel (x, y), if inside the window.
    pub fn index(&self, x: u32, y: u32) -> Option<usize> {
        let w = &self.window;
        (x >= w.x0 && y >= w.y0 && x < w.x0 + w.width && y < w.y0 + w.height)
            .then(|| ((y - w.y0) * w.width + (x - w.x0)) as usize)
    }
}
