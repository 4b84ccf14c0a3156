//! Terminal graphics: which protocol to use, and our own per-frame encoders.
//!
//! - kitty: one fixed image id and placement, raw RGB (f=24); zlib (o=z) when the
//!   terminal is remote, a temporary file (t=t) when it is local, chunks of 4096
//!   base64 bytes otherwise.
//! - sixel: icy_sixel without dithering (dithering makes every frame shimmer).
//! - iTerm2: inline PNG, fast compression.
//! - half-blocks: '▀' with foreground = upper pixel, background = lower pixel,
//!   drawn straight into ratatui cells (the fallback, and the mode of snapshot tests).
//!
//! Inside tmux every escape is wrapped for passthrough. Frames are written
//! inside synchronized output (`CSI ? 2026 h/l`) in one write.

use std::io::Write;

use base64::Engine as _;
use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::style::Color;

use crate::render::image::RgbImage;

pub use crate::editor::session::Protocol;

/// The `--graphics` choice.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum GraphicsChoice {
    /// Ask the terminal (ratatui-image's query, short timeout), then environment hints.
    #[default]
    Auto,
    /// kitty graphics protocol.
    Kitty,
    /// DEC sixel.
    Sixel,
    /// iTerm2 inline images.
    Iterm2,
    /// Unicode half blocks.
    Halfblocks,
}

/// What the terminal can show and how big its cells are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TerminalGraphics {
    /// Protocol in use.
    pub protocol: Protocol,
    /// Cell size in pixels (width, height).
    pub cell_px: (u16, u16),
    /// Running inside tmux (escapes need passthrough).
    pub tmux: bool,
    /// The terminal is on another machine (SSH): prefer compression over files.
    pub remote: bool,
}

/// Cell size assumed when the terminal does not say.
pub const DEFAULT_CELL_PX: (u16, u16) = (8, 16);

/// Works out the graphics protocol. `Auto` queries the terminal through
/// ratatui-image's picker (pure-Rust detection, 300 ms timeout) and falls back to
/// half-blocks; explicit choices never query.
pub fn detect(choice: GraphicsChoice) -> TerminalGraphics {
    let tmux = std::env::var_os("TMUX").is_some_and(|v| !v.is_empty());
    let remote =
        std::env::var_os("SSH_CONNECTION").is_some() || std::env::var_os("SSH_TTY").is_some();
    let cell_px = window_cell_px().unwrap_or(DEFAULT_CELL_PX);
    let fixed = |protocol| TerminalGraphics {
        protocol,
        cell_px,
        tmux,
        remote,
    };
    match choice {
        GraphicsChoice::Kitty => fixed(Protocol::Kitty),
        GraphicsChoice::Sixel => fixed(Protocol::Sixel),
        GraphicsChoice::Iterm2 => fixed(Protocol::Iterm2),
        GraphicsChoice::Halfblocks => fixed(Protocol::Halfblocks),
        GraphicsChoice::Auto => {
            use ratatui_image::picker::cap_parser::QueryStdioOptions;
            use ratatui_image::picker::{Picker, ProtocolType};
            let options = QueryStdioOptions {
                timeout_ms: 300,
                ..Default::default()
            };
            match Picker::from_query_stdio_with_options(options) {
                Ok(picker) => {
                    let fs = picker.font_size();
                    let protocol = match picker.protocol_type() {
                        ProtocolType::Kitty => Protocol::Kitty,
                        ProtocolType::Sixel => Protocol::Sixel,
                        ProtocolType::Iterm2 => Protocol::Iterm2,
                        ProtocolType::Halfblocks => Protocol::Halfblocks,
                    };
                    let cell_px = if fs.width > 0 && fs.height > 0 {
                        (fs.width, fs.height)
                    } else {
                        cell_px
                    };
                    TerminalGraphics {
                        protocol,
                        cell_px,
                        tmux: picker.tmux_detected() || tmux,
                        remote,
                    }
                }
                Err(_) => fixed(Protocol::Halfblocks),
            }
        }
    }
}

/// Cell size from the terminal's reported window size in pixels, when it reports one.
fn window_cell_px() -> Option<(u16, u16)> {
    let ws = crossterm::terminal::window_size().ok()?;
    (ws.width > 0 && ws.height > 0 && ws.columns > 0 && ws.rows > 0)
        .then(|| (ws.width / ws.columns, ws.height / ws.rows))
        .filter(|(w, h)| *w > 0 && *h > 0)
}

/// Wraps an escape sequence for tmux passthrough.
pub fn tmux_wrap(escape: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(escape.len() + 16);
    out.extend_from_slice(b"\x1bPtmux;");
    for &b in escape {
        if b == 0x1b {
            out.push(0x1b);
        }
        out.push(b);
    }
    out.extend_from_slice(b"\x1b\\");
    out
}

/// Image id visage's frames use with the kitty protocol.
pub const KITTY_IMAGE_ID: u32 = 7331;

/// Source thumbnails use the ids after the frame's, one each, at most this many.
pub const KITTY_THUMBNAIL_IDS: u32 = 64;

/// How kitty receives the pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KittyTransport {
    /// Inline base64 chunks, raw.
    Direct,
    /// Inline base64 chunks, zlib-compressed (remote terminals).
    Zlib,
    /// A temporary file the terminal reads and deletes (local terminals).
    TempFile,
}

/// Encodes a frame for kitty, replacing the previous one in place (fixed image and
/// placement ids), scaled to `cells` (columns, rows).
pub fn encode_kitty(
    image: &RgbImage,
    cells: (u16, u16),
    transport: KittyTransport,
) -> std::io::Result<Vec<u8>> {
    encode_kitty_with_id(image, cells, transport, KITTY_IMAGE_ID)
}

/// [`encode_kitty`] for the image `id` (thumbnails have their own ids).
pub fn encode_kitty_with_id(
    image: &RgbImage,
    cells: (u16, u16),
    transport: KittyTransport,
    id: u32,
) -> std::io::Result<Vec<u8>> {
    let b64 = base64::engine::general_purpose::STANDARD;
    let header = format!(
        "a=T,f=24,s={},v={},i={id},p=1,q=2,C=1,c={},r={}",
        image.width, image.height, cells.0, cells.1
    );
    let mut out = Vec::new();
    match transport {
        KittyTransport::TempFile => {
            // kitty only deletes temporary files whose path contains this marker.
            let path = std::env::temp_dir().join(format!(
                "visage-tty-graphics-protocol-{}.rgb",
                std::process::id()
            ));
            std::fs::write(&path, &image.pixels)?;
            let payload = b64.encode(path.to_string_lossy().as_bytes());
            write!(out, "\x1b_G{header},t=t;{payload}\x1b\\")?;
        }
        KittyTransport::Direct | KittyTransport::Zlib => {
            let data = if transport == KittyTransport::Zlib {
                let mut z =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
                z.write_all(&image.pixels)?;
                z.finish()?
            } else {
                image.pixels.clone()
            };
            let payload = b64.encode(&data);
            let extra = if transport == KittyTransport::Zlib {
                ",o=z"
            } else {
                ""
            };
            let chunks: Vec<&[u8]> = payload.as_bytes().chunks(4096).collect();
            for (k, chunk) in chunks.iter().enumerate() {
                let more = u8::from(k + 1 < chunks.len());
                if k == 0 {
                    write!(out, "\x1b_G{header}{extra},m={more};")?;
                } else {
                    write!(out, "\x1b_Gm={more};")?;
                }
                out.extend_from_slice(chunk);
                out.extend_from_slice(b"\x1b\\");
            }
        }
    }
    Ok(out)
}

/// Deletes visage's kitty frame (before overlays are drawn over the viewport).
pub fn kitty_delete() -> Vec<u8> {
    format!("\x1b_Ga=d,d=i,i={KITTY_IMAGE_ID},q=2\x1b\\").into_bytes()
}

/// Deletes every kitty image visage placed: the frame and the thumbnails
/// (on exit).
pub fn kitty_delete_all() -> Vec<u8> {
    (KITTY_IMAGE_ID..=KITTY_IMAGE_ID + KITTY_THUMBNAIL_IDS)
        .flat_map(|id| format!("\x1b_Ga=d,d=I,i={id},q=2\x1b\\").into_bytes())
        .collect()
}

/// Encodes a frame as sixel: 256-colour palette (Wu), no dithering.
pub fn encode_sixel(image: &RgbImage) -> Result<Vec<u8>, String> {
    let mut rgba = Vec::with_capacity(image.pixels.len() / 3 * 4);
    for p in image.pixels.chunks(3) {
        rgba.extend_from_slice(&[p[0], p[1], p[2], 255]);
    }
    let options = icy_sixel::EncodeOptions {
        max_colors: 256,
        diffusion: 0.0,
        quantize_method: icy_sixel::QuantizeMethod::Wu,
    };
    icy_sixel::sixel_encode(&rgba, image.width as usize, image.height as usize, &options)
        .map(String::into_bytes)
        .map_err(|e| format!("sixel encoding failed: {e}"))
}

/// Encodes a frame as an iTerm2 inline image (PNG) sized to `cells`.
pub fn encode_iterm2(image: &RgbImage, cells: (u16, u16)) -> Result<Vec<u8>, String> {
    let mut png = Vec::new();
    {
        use image::ImageEncoder;
        let encoder = image::codecs::png::PngEncoder::new_with_quality(
            &mut png,
            image::codecs::png::CompressionType::Fast,
            image::codecs::png::FilterType::Sub,
        );
        encoder
            .write_image(
                &image.pixels,
                image.width,
                image.height,
                image::ExtendedColorType::Rgb8,
            )
            .map_err(|e| format!("PNG encoding failed: {e}"))?;
    }
    let b64 = base64::engine::general_purpose::STANDARD.encode(&png);
    Ok(format!(
        "\x1b]1337;File=inline=1;size={};width={};height={};preserveAspectRatio=0:{b64}\x07",
        png.len(),
        cells.0,
        cells.1
    )
    .into_bytes())
}

/// Draws `image` (width = area width, height = 2 × area height) into the cells of
/// `area` as half blocks.
pub fn draw_halfblocks(buf: &mut Buffer, area: Rect, image: &RgbImage) {
    for y in 0..area.height {
        for x in 0..area.width {
            let (px, py) = (x as u32, 2 * y as u32);
            if px >= image.width || py >= image.height {
                continue;
            }
            let top = image.pixel(px, py);
            let bottom = if py + 1 < image.height {
                image.pixel(px, py + 1)
            } else {
                top
            };
            if let Some(cell) = buf.cell_mut((area.x + x, area.y + y)) {
                cell.set_symbol("▀")
                    .set_fg(Color::Rgb(top[0], top[1], top[2]))
                    .set_bg(Color::Rgb(bottom[0], bottom[1], bottom[2]));
            }
        }
    }
}

/// Marks the cells of `area` so ratatui leaves them alone (an image protocol owns them).
pub fn reserve_cells(buf: &mut Buffer, area: Rect) {
    for y in area.top()..area.bottom() {
        for x in area.left()..area.right() {
            if let Some(cell) = buf.cell_mut((x, y)) {
                cell.set_diff_option(ratatui::buffer::CellDiffOption::Skip);
            }
        }
    }
}

/// Where and how a frame goes on screen: the protocol, the cells it covers,
/// the pixels it should have, and the transport details.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageTarget {
    /// Protocol in use.
    pub protocol: Protocol,
    /// Columns and rows covered.
    pub cells: (u16, u16),
    /// Full-size pixels (sixel draws 1:1; half blocks are 1 × 2 per cell).
    pub full: (u32, u32),
    /// How kitty receives the pixels.
    pub kitty: KittyTransport,
    /// Wrap escapes for tmux passthrough.
    pub tmux: bool,
    /// The kitty image id.
    pub kitty_id: u32,
}

impl ImageTarget {
    /// The target for a viewport of `cells` on this terminal.
    pub fn new(graphics: &TerminalGraphics, cells: (u16, u16)) -> ImageTarget {
        let full = match graphics.protocol {
            Protocol::Halfblocks => (cells.0 as u32, 2 * cells.1 as u32),
            _ => (
                cells.0 as u32 * graphics.cell_px.0 as u32,
                cells.1 as u32 * graphics.cell_px.1 as u32,
            ),
        };
        ImageTarget {
            protocol: graphics.protocol,
            cells,
            full,
            kitty: if graphics.remote {
                KittyTransport::Zlib
            } else {
                KittyTransport::TempFile
            },
            tmux: graphics.tmux,
            kitty_id: KITTY_IMAGE_ID,
        }
    }

    /// The target of source thumbnail `index`: its own kitty image id, sent
    /// inline (thumbnails are small; a shared temporary file would race).
    pub fn thumbnail(graphics: &TerminalGraphics, cells: (u16, u16), index: usize) -> ImageTarget {
        let base = ImageTarget::new(graphics, cells);
        ImageTarget {
            kitty: if graphics.remote {
                KittyTransport::Zlib
            } else {
                KittyTransport::Direct
            },
            kitty_id: KITTY_IMAGE_ID + 1 + (index as u32 % KITTY_THUMBNAIL_IDS),
            ..base
        }
    }

    /// Encodes a rendered frame for the terminal (nothing for half blocks,
    /// which are drawn into the cell buffer).
    pub fn encode(&self, image: &RgbImage) -> Result<Vec<u8>, String> {
        let bytes = match self.protocol {
            Protocol::Halfblocks => return Ok(Vec::new()),
            Protocol::Kitty => encode_kitty_with_id(image, self.cells, self.kitty, self.kitty_id)
                .map_err(|e| e.to_string())?,
            Protocol::Iterm2 => encode_iterm2(image, self.cells)?,
            Protocol::Sixel => {
                if (image.width, image.height) != self.full {
                    encode_sixel(&image.resized(self.full.0, self.full.1))?
                } else {
                    encode_sixel(image)?
                }
            }
        };
        Ok(if self.tmux { tmux_wrap(&bytes) } else { bytes })
    }
}

/// Appends an encoded image placed at the viewport's top-left cell, with the
/// cursor saved and restored around it (nothing when there is no image).
pub fn place_image(out: &mut Vec<u8>, viewport: Rect, encoded: &[u8]) {
    if encoded.is_empty() {
        return;
    }
    out.extend_from_slice(format!("\x1b7\x1b[{};{}H", viewport.y + 1, viewport.x + 1).as_bytes());
    out.extend_from_slice(encoded);
    out.extend_from_slice(b"\x1b8");
}

/// Begin and end of synchronized output.
pub const SYNC_BEGIN: &[u8] = b"\x1b[?2026h";
/// End of synchronized output.
pub const SYNC_END: &[u8] = b"\x1b[?2026l";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tmux_passthrough_doubles_escapes() {
        assert_eq!(
            tmux_wrap(b"\x1b_Ga\x1b\\"),
            b"\x1bPtmux;\x1b\x1b_Ga\x1b\x1b\\\x1b\\".to_vec()
        );
    }

    #[test]
    fn halfblocks_carry_both_pixels() {
        let mut img = RgbImage::new(2, 2, [0, 0, 0]);
        img.pixels[..3].copy_from_slice(&[255, 0, 0]);
        img.pixels[6..9].copy_from_slice(&[0, 0, 255]);
        let area = Rect::new(0, 0, 2, 1);
        let mut buf = Buffer::empty(area);
        draw_halfblocks(&mut buf, area, &img);
        let c = &buf[(0, 0)];
        assert_eq!(c.symbol(), "▀");
        assert_eq!(c.fg, Color::Rgb(255, 0, 0));
        assert_eq!(c.bg, Color::Rgb(0, 0, 255));
    }

    #[test]
    fn iterm2_is_one_osc_with_a_png() {
        let img = RgbImage::new(4, 3, [10, 20, 30]);
        let bytes = encode_iterm2(&img, (2, 1)).unwrap();
        let text = String::from_utf8(bytes).unwrap();
        assert!(text.starts_with("\x1b]1337;File=inline=1;") && text.ends_with('\x07'));
        let b64 = text.rsplit(':').next().unwrap().trim_end_matches('\x07');
        let png = base64::engine::general_purpose::STANDARD
            .decode(b64)
            .unwrap();
        let back = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(back.into_raw(), img.pixels);
    }
}
