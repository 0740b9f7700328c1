//! The reflection model: Lambert diffuse plus a GGX (Trowbridge–Reitz) microfacet specular lobe
//! with Smith height-correlated masking and Schlick's Fresnel, the usual metallic/roughness model.

use std::f64::consts::PI;

use nalgebra::Vector3;

use super::Appearance;

/// Reflected radiance factor f_r · cos θ_l for unit normal `n`, unit direction to the viewer `v`
/// and unit direction to the light `l`, per linear RGB channel.
///
/// `tangent` is the brushing direction for anisotropic appearances (Burley's aspect ratio on the
/// GGX distribution). `spread` is the light's angular radius as seen from the point (radius /
/// distance): a sphere light widens the lobe to α + spread / 2 with the energy kept (Karis).
pub(crate) fn brdf_cos(
    a: &Appearance,
    n: &Vector3<f64>,
    v: &Vector3<f64>,
    l: &Vector3<f64>,
    tangent: Option<&Vector3<f64>>,
    spread: f64,
) -> [f64; 3] {
    let nl = n.dot(l);
    let nv = n.dot(v).max(1e-4);
    if nl <= 0.0 {
        return [0.0; 3];
    }
    let h = (v + l).normalize();
    let nh = n.dot(&h).max(0.0);
    let vh = v.dot(&h).max(0.0);
    let alpha = (a.roughness * a.roughness).max(1e-4);
    let widened = (alpha + spread / 2.0).min(1.0);
    let energy = (alpha / widened).powi(2);
    let a2 = alpha * alpha;
    let d = match tangent {
        Some(t) if a.anisotropy > 0.0 => {
            let aspect = (1.0 - 0.9 * a.anisotropy.min(1.0)).sqrt();
            let (ax, ay) = (widened / aspect, widened * aspect);
            let t = (t - n * n.dot(t))
                .try_normalize(1e-12)
                .unwrap_or_else(|| n.cross(v));
            let b = n.cross(&t);
            let (ht, hb) = (h.dot(&t) / ax, h.dot(&b) / ay);
            let k = ht * ht + hb * hb + nh * nh;
            1.0 / (PI * ax * ay * k * k)
        }
        _ => {
            let w2 = widened * widened;
            let denom = nh * nh * (w2 - 1.0) + 1.0;
            w2 / (PI * denom * denom)
        }
    } * energy;
    let lambda_v = nl * (nv * nv * (1.0 - a2) + a2).sqrt();
    let lambda_l = nv * (nl * nl * (1.0 - a2) + a2).sqrt();
    let vis = 0.5 / (lambda_v + lambda_l).max(1e-12);
    let fw = (1.0 - vh).powi(5);
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let f0 = a.specular * (1.0 - a.metallic) + a.base_color[c] * a.metallic;
        let f = f0 + (1.0 - f0) * fw;
        let diffuse = (1.0 - a.metallic) * a.base_color[c] / PI;
        *o = (diffuse * (1.0 - f) + d * vis * f) * nl;
    }
    out
}

/// Radiance reflected from a uniform ambient (sky) radiance: diffuse albedo plus the
/// split-sum approximation of the specular lobe's directional albedo.
pub(crate) fn ambient(
    a: &Appearance,
    n: &Vector3<f64>,
    v: &Vector3<f64>,
    sky: &[f64; 3],
) -> [f64; 3] {
    let nv = n.dot(v).clamp(0.0, 1.0);
    // Karis' analytic fit of the environment BRDF (scale, bias) for a given roughness and n·v.
    let r = a.roughness;
    let c0 = [-1.0, -0.0275, -0.572, 0.022];
    let c1 = [1.0, 0.0425, 1.04, -0.04];
    let rr = [
        r * c0[0] + c1[0],
        r * c0[1] + c1[1],
        r * c0[2] + c1[2],
        r * c0[3] + c1[3],
    ];
    let a004 = (rr[0] * rr[0]).min((-9.28 * nv).exp2()) * rr[0] + rr[1];
    let scale = a004 * -1.04 + rr[2];
    let bias = a004 * 1.04 + rr[3];
    let mut out = [0.0; 3];
    for (c, o) in out.iter_mut().enumerate() {
        let f0 = a.specular * (1.0 - a.metallic) + a.base_color[c] * a.metallic;
        let spec = f0 * scale + bias;
        let diffuse = (1.0 - a.metallic) * a.base_color[c];
        *o = sky[c] * (diffuse + spec);
    }
    out
}
