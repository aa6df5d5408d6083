//! `#[guard]`: the one line that keeps a Rust panic from reaching Python as pyo3's
//! `PanicException` (a `BaseException` that `except Exception` does not catch).
//!
//! Put above a `#[pyfunction]` or a `#[pymethods]` impl block. Each function's body runs inside
//! `crate::errors::guarded(entry, || body)`, which catches the unwind and returns
//! `oxyline.SolverError` naming the entry and the panic's message. A body returning
//! `Result<T, E>` keeps its signature (`E: From<PyErr>`); any other return type `T` becomes
//! `PyResult<T>`, which pyo3 accepts at every entry kind.

use proc_macro::TokenStream;
use quote::ToTokens;
use syn::{Block, ImplItem, Item, ReturnType, Signature, Type, parse_macro_input, parse_quote};

/// Guard every Python entry of the item (a function, or each method of an impl block).
#[proc_macro_attribute]
pub fn guard(attr: TokenStream, item: TokenStream) -> TokenStream {
    if !attr.is_empty() {
        return syn::Error::new(
            proc_macro2::Span::call_site(),
            "#[guard] takes no arguments",
        )
        .to_compile_error()
        .into();
    }
    let mut item = parse_macro_input!(item as Item);
    match &mut item {
        Item::Fn(f) => wrap(&mut f.sig, &mut f.block, None),
        Item::Impl(imp) => {
            let owner = imp.self_ty.to_token_stream().to_string().replace(' ', "");
            for it in &mut imp.items {
                if let ImplItem::Fn(m) = it {
                    // pyo3's GC hooks have fixed signatures and must not call into Python
                    let name = m.sig.ident.to_string();
                    if name != "__traverse__" && name != "__clear__" {
                        wrap(&mut m.sig, &mut m.block, Some(&owner));
                    }
                }
            }
        }
        other => {
            return syn::Error::new_spanned(other, "#[guard] goes on a fn or an impl block")
                .to_compile_error()
                .into();
        }
    }
    item.into_token_stream().into()
}

/// Whether `ty` is spelled as a `Result` (`PyResult<T>`, `Result<T, E>`, any path ending so).
fn is_result(ty: &Type) -> bool {
    match ty {
        Type::Path(p) => p
            .path
            .segments
            .last()
            .is_some_and(|s| s.ident == "Result" || s.ident == "PyResult"),
        _ => false,
    }
}

fn wrap(sig: &mut Signature, block: &mut Block, owner: Option<&str>) {
    let entry = match owner {
        Some(o) => format!("{o}.{}", sig.ident),
        None => sig.ident.to_string(),
    };
    let ret: Type = match &sig.output {
        ReturnType::Default => parse_quote!(()),
        ReturnType::Type(_, ty) => (**ty).clone(),
    };
    let body = block.clone();
    let new: Block = if is_result(&ret) {
        parse_quote!({
            match crate::errors::guarded(#entry, || -> #ret #body) {
                ::core::result::Result::Ok(r) => r,
                ::core::result::Result::Err(e) => ::core::result::Result::Err(e.into()),
            }
        })
    } else {
        sig.output = parse_quote!(-> ::pyo3::PyResult<#ret>);
        parse_quote!({ crate::errors::guarded(#entry, || -> #ret #body) })
    };
    *block = new;
}
