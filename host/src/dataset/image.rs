//! Image loading: any supported file (PNG, JPEG, PNM, BMP, TIFF), 8/16-bit,
//! gray or colour, to an 8-bit gray buffer.
use super::DatasetError;
use image::DynamicImage;
use std::path::Path;

/// An 8-bit gray image, rows packed (`stride == width`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GrayImage {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

impl GrayImage {
    /// A view for the core.
    pub fn view(
        &self,
    ) -> Result<phototraverse_core::image::ImageView<'_>, phototraverse_core::image::ImageError>
    {
        phototraverse_core::image::ImageView::new(
            &self.data,
            self.width as usize,
            self.height as usize,
        )
    }
}

/// Loads `path` as 8-bit gray. 16-bit images are scaled by their full range
/// (`v >> 8`); colour is converted with Rec. 709 luma weights (the `image`
/// crate's conversion).
pub fn load_gray(path: &Path) -> Result<GrayImage, DatasetError> {
    let img = image::ImageReader::open(path)
        .map_err(|source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .with_guessed_format()
        .map_err(|source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .decode()
        .map_err(|e| DatasetError::Image {
            path: path.to_path_buf(),
            problem: e.to_string(),
        })?;
    Ok(to_gray8(img))
}

/// Converts a decoded image to 8-bit gray.
pub fn to_gray8(img: DynamicImage) -> GrayImage {
    let (width, height) = (img.width(), img.height());
    let data = match img {
        DynamicImage::ImageLuma8(g) => g.into_raw(),
        DynamicImage::ImageLuma16(_)
        | DynamicImage::ImageLumaA16(_)
        | DynamicImage::ImageRgb16(_)
        | DynamicImage::ImageRgba16(_)
        | DynamicImage::ImageRgb32F(_)
        | DynamicImage::ImageRgba32F(_) => {
            let g16 = img.to_luma16().into_raw();
            let mut out = vec![0u8; g16.len()];
            phototraverse_core::image::scale_u16_to_u8(&g16, &mut out, 16);
            out
        }
        other => other.to_luma8().into_raw(),
    };
    GrayImage {
        width,
        height,
        data,
    }
}

/// Width and height from the file header only (cheap: used to check a whole dataset at open).
pub fn image_size(path: &Path) -> Result<(u32, u32), DatasetError> {
    image::ImageReader::open(path)
        .map_err(|source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .with_guessed_format()
        .map_err(|source| DatasetError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .into_dimensions()
        .map_err(|e| DatasetError::Image {
            path: path.to_path_buf(),
            problem: e.to_string(),
        })
}
