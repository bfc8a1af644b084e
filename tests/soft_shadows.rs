//! Soft shadows at the defaults: no isolated dark pixels. A large object by
//! a wall under the desk's rect light casts a wide penumbra on the wall and
//! the floor; a pixel whose few first shadow rays all happen to be blocked
//! must not go dark among lit neighbours (a user sees such pixels as grain).

mod common;
use common::Desk;
use common::asset::{AssetSpec, write_asset};

use arlux::image_io::Image;
use arlux::scene::Scene;

/// Pixels whose value in `img` is under 20% of each of their four
/// neighbours' while those are lit (above 2% of the frame's 99th
/// percentile), among the pixels `counted` says (with their neighbours).
fn isolated_dark(img: &Image, counted: impl Fn(usize) -> bool) -> Vec<(usize, usize)> {
    let (w, h) = (img.width as usize, img.height as usize);
    let lum: Vec<f32> = (img.pixels.iter()).map(|p| p.element_sum()).collect();
    let mut sorted = lum.clone();
    sorted.sort_by(f32::total_cmp);
    let lit = 0.02 * sorted[sorted.len() * 99 / 100];
    let mut out = Vec::new();
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let i = y * w + x;
            let around = [i - 1, i + 1, i - w, i + w];
            if counted(i)
                && around
                    .iter()
                    .all(|&j| counted(j) && lum[j] > lit && lum[i] < 0.2 * lum[j])
            {
                out.push((x, y));
            }
        }
    }
    out
}

#[test]
fn a_wide_penumbra_has_no_isolated_dark_pixels() {
    let desk = Desk::new();
    let spec = AssetSpec {
        triangles: 4_000,
        texture: 64,
        width: 0.9,
        height: 1.1,
        groove_deg: 0.0,
        grooves: 1,
    };
    write_asset(&desk.path("geometry"), "cabinet", &spec);
    let text = std::fs::read_to_string(desk.path("scene.toml")).unwrap();
    let at = text.find("[[virtual]]").unwrap();
    let text = format!(
        "{}[[virtual]]\nname = \"cabinet\"\nmesh = \"geometry/cabinet.gltf\"\ntranslate = [-0.4, 0.0, -1.5]\n",
        &text[..at]
    );
    std::fs::write(desk.path("scene.toml"), text).unwrap();
    let scene = Scene::load(desk.path("scene.toml")).unwrap();
    let (out, _) = common::render_default(&scene);
    let c = &out.composite;
    // The image, everywhere.
    let dark = isolated_dark(&c.image, |_| true);
    assert!(
        dark.is_empty(),
        "{} isolated dark pixels in the image: {dark:?}",
        dark.len()
    );
    // The direct light layer, among pixels of one kind (all room, or all
    // object): where coverage is partial the layer holds one sample's
    // light, not the pixel's mix the image shows.
    let room = isolated_dark(&c.direct, |i| c.alpha[i] == 0.0);
    let object = isolated_dark(&c.direct, |i| c.alpha[i] == 1.0);
    assert!(
        room.is_empty() && object.is_empty(),
        "isolated dark pixels of direct light: {room:?} on the room, {object:?} on the object"
    );
}
