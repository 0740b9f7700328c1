//! Recipes: an ordered list of typed variables and the encoding of their values in data packages.

use super::types::{DataType, Value};
use thiserror::Error;

/// Why values do not fit a recipe.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RecipeError {
    /// The data payload has the wrong length for the recipe.
    #[error("recipe {recipe_id} expects {expected} bytes of values, got {got}")]
    WrongLength {
        /// Recipe id.
        recipe_id: u8,
        /// Expected bytes.
        expected: usize,
        /// Bytes present.
        got: usize,
    },
    /// A value count differs from the recipe's variable count.
    #[error("recipe {recipe_id} has {expected} variables, got {got} values")]
    WrongCount {
        /// Recipe id.
        recipe_id: u8,
        /// Variables in the recipe.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A value has another type than its variable.
    #[error("variable {name} is {expected}, got a {got} value")]
    WrongType {
        /// Variable name.
        name: String,
        /// Its type.
        expected: DataType,
        /// The value's type.
        got: DataType,
    },
}

/// A set-up recipe: id, names and their types.
#[derive(Debug, Clone, PartialEq)]
pub struct Recipe {
    /// Recipe id (the output recipe in v1 has none and uses 0).
    pub id: u8,
    /// Variable names in order.
    pub names: Vec<String>,
    /// Their types.
    pub types: Vec<DataType>,
    payload_len: usize,
}

impl Recipe {
    /// A recipe from names and matching types.
    pub fn new(id: u8, names: Vec<String>, types: Vec<DataType>) -> Recipe {
        let payload_len = types.iter().map(|t| t.size()).sum();
        Recipe {
            id,
            names,
            types,
            payload_len,
        }
    }

    /// Bytes of the values in a data package.
    pub fn payload_len(&self) -> usize {
        self.payload_len
    }

    /// Position of a variable in the recipe.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.names.iter().position(|n| n == name)
    }

    /// Decodes a data payload into `out` (cleared first), reusing its allocation.
    pub fn decode_into(&self, bytes: &[u8], out: &mut Vec<Value>) -> Result<(), RecipeError> {
        if bytes.len() != self.payload_len {
            return Err(RecipeError::WrongLength {
                recipe_id: self.id,
                expected: self.payload_len,
                got: bytes.len(),
            });
        }
        out.clear();
        let mut at = 0;
        for &ty in &self.types {
            // The length check above guarantees every value is present.
            if let Some(v) = Value::decode(ty, &bytes[at..]) {
                out.push(v);
            }
            at += ty.size();
        }
        Ok(())
    }

    /// Decodes a data payload into a new vector.
    pub fn decode(&self, bytes: &[u8]) -> Result<Vec<Value>, RecipeError> {
        let mut out = Vec::with_capacity(self.types.len());
        self.decode_into(bytes, &mut out)?;
        Ok(out)
    }

    /// Checks that `values` match the recipe, then appends their encoding to `out`.
    pub fn encode(&self, values: &[Value], out: &mut Vec<u8>) -> Result<(), RecipeError> {
        if values.len() != self.types.len() {
            return Err(RecipeError::WrongCount {
                recipe_id: self.id,
                expected: self.types.len(),
                got: values.len(),
            });
        }
        for ((v, &t), name) in values.iter().zip(&self.types).zip(&self.names) {
            if v.data_type() != t {
                return Err(RecipeError::WrongType {
                    name: name.clone(),
                    expected: t,
                    got: v.data_type(),
                });
            }
        }
        out.reserve(self.payload_len);
        values.iter().for_each(|v| v.encode(out));
        Ok(())
    }
}
